# A JupyterHub to try the course on ONE machine before the real hub (docs/ta.md, section 2b, "A trial hub").
#
#   jupyterhub -f scripts/jupyterhub_trial_config.py
#
# Everything listens on 127.0.0.1; any user name logs in with the password HUB_PASSWORD (JupyterHub's
# DummyAuthenticator), and each user's server runs as the account that started the hub, with its home in
# HUB_DIR/home/<name> (JupyterHub's SimpleLocalProcessSpawner: JupyterHub's own "for testing" spawner, no
# system accounts). Never expose it to a network: it is a trial, not a hub for a class (for that, TLJH or Z2JH).
#
# Settings (environment variables, all optional):
#   HUB_DIR          the hub's state: database, cookie secret, pid files, users' homes   (default ./hub-trial)
#   HUB_PORT         the port students' browsers use                                      (default 8000)
#   HUB_PASSWORD     the trial's one password                                             (default "trial")
#   HUB_USER_PYTHON  the Python of the users' environment, which holds the kit's wheel    (default: the hub's)
#   HUB_PROXY        configurable-http-proxy                 (default .hub/node_modules/.bin/ of the kit, where
#                                                             scripts/install-hub.sh puts it, else from PATH)
# tests/test_hub.py starts its hub with this file and these variables.
import os
import shutil
import socket
import sys
from pathlib import Path

c = get_config()  # noqa: F821 - JupyterHub's config loader provides it

KIT = Path(__file__).resolve().parents[1]
state = Path(os.environ.get("HUB_DIR", "hub-trial")).resolve()
(state / "home").mkdir(parents=True, exist_ok=True)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


proxy = os.environ.get("HUB_PROXY") or str(KIT / ".hub" / "node_modules" / ".bin" / "configurable-http-proxy")
if not Path(proxy).exists():
    proxy = shutil.which("configurable-http-proxy") or proxy
c.JupyterHub.bind_url = f"http://127.0.0.1:{int(os.environ.get('HUB_PORT', '8000'))}"
c.JupyterHub.hub_ip = "127.0.0.1"
c.JupyterHub.hub_port = _free_port()
c.ConfigurableHTTPProxy.api_url = f"http://127.0.0.1:{_free_port()}"
c.ConfigurableHTTPProxy.command = [proxy]
c.ConfigurableHTTPProxy.pid_file = str(state / "proxy.pid")
c.JupyterHub.db_url = f"sqlite:///{state / 'hub.sqlite'}"
c.JupyterHub.cookie_secret_file = str(state / "cookie_secret")
c.JupyterHub.pid_file = str(state / "hub.pid")
c.JupyterHub.authenticator_class = "dummy"
c.DummyAuthenticator.password = os.environ.get("HUB_PASSWORD", "trial")
c.Authenticator.allow_all = True
c.JupyterHub.spawner_class = "simple"
c.SimpleLocalProcessSpawner.home_dir_template = str(state / "home" / "{username}")
c.Spawner.cmd = [os.environ.get("HUB_USER_PYTHON", sys.executable), "-m", "jupyterhub.singleuser"]
c.Spawner.args = (["--allow-root"] if os.geteuid() == 0 else []) + [
    "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate"]
c.Spawner.default_url = "/lab"
c.Spawner.start_timeout = 300  # the first start of a user's server imports JupyterLab: slow on a busy machine
c.Spawner.http_timeout = 300
