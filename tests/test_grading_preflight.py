"""Why bubblewrap fails on a machine, named with its fix (issue 28, item 4): each cause from the
facts that show it (a sysctl, a container's marks), and this machine's own facts as read."""

from __future__ import annotations

import pytest

from dtscal_lib.grading import preflight

HEALTHY = {"bwrap": "/usr/bin/bwrap", "max_user_namespaces": 15000, "unprivileged_userns_clone": None,
           "apparmor_restrict": 0, "container": None, "seccomp": 0, "root": False}

CAUSES = {  # facts that differ from a healthy machine -> words of the cause, words of the fix
    "not installed": ({"bwrap": None}, "not installed", "install-sandbox.sh"),
    "no user namespaces": ({"max_user_namespaces": 0}, "max_user_namespaces is 0", "user.max_user_namespaces="),
    "debian sysctl": ({"unprivileged_userns_clone": 0}, "unprivileged_userns_clone is 0",
                      "kernel.unprivileged_userns_clone=1"),
    "ubuntu 24.04 apparmor": ({"apparmor_restrict": 1}, "AppArmor", "userns,"),
    "docker seccomp": ({"container": "docker", "seccomp": 2}, "Docker's default seccomp",
                       "--security-opt seccomp=unconfined"),
    "kubernetes": ({"container": "kubernetes", "seccomp": 2}, "Kubernetes pod", "hostUsers: false"),
}


@pytest.mark.parametrize("name", list(CAUSES))
def test_each_cause_is_named_with_its_fix(name):
    changed, why, fix = CAUSES[name]
    causes = preflight.diagnose({**HEALTHY, **changed}, "bwrap: setting up uid map: Permission denied")
    assert len(causes) == 1, causes
    assert why in causes[0].why and fix in causes[0].fix, causes[0]


def test_an_unknown_cause_quotes_bubblewrap():
    causes = preflight.diagnose(HEALTHY, "bwrap: Creating new namespace failed: Resource exhausted")
    assert "Resource exhausted" in causes[0].why and "docs/ta.md" in causes[0].fix


def test_this_machines_facts_are_read(monkeypatch):
    f = preflight.facts()
    assert set(f) == set(HEALTHY)
    monkeypatch.setenv("PATH", "/nonexistent")
    assert preflight.facts()["bwrap"] is None
    monkeypatch.setenv("KUBERNETES_SERVICE_HOST", "10.0.0.1")
    assert preflight.facts()["container"] == "kubernetes"
