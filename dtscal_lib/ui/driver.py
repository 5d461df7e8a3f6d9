"""What the live tools' widget-free drivers share: RECONNECT's messages and closing as a context manager."""

from __future__ import annotations

from ..errors import DtscalError


def dtps_link_of(source, robot: str):
    """Where COMMIT goes over DTPS: the ``dtps:`` source's robot, else ``robot`` at ``ROBOT.local``."""
    from ..dtps_link import parse_dtps_spec

    link = getattr(source, "dtps", None)
    return link if link is not None else parse_dtps_spec(robot or "")


class LoopDriver:
    """A driver with a frame loop (``self.loop``) on a source (``self.spec``); subclasses define ``close``."""

    def _reconnect(self, kept: str = "") -> tuple[str, str]:
        """RECONNECT: re-open the source; ``(message, kind)``, ``kept`` says what survives it."""
        try:
            self.loop.reconnect()
        except DtscalError as exc:
            return f"RECONNECT failed: {exc}", "error"
        return f"reconnecting to {self.spec}{kept}", "info"

    def close(self) -> None:  # pragma: no cover - every driver has its own
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
