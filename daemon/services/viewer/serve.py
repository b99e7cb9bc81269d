"""The Rerun web viewer and its gRPC proxy bound to one address (the ``serve`` sink).

Rerun's own ``serve_grpc`` and ``serve_web_viewer`` listen on every interface (0.0.0.0) with no way
to say otherwise, so the viewer's ``serve`` sink runs Rerun's command-line server instead, which takes
``--bind``: ``rerun --serve-web --bind HOST --port GRPC --web-viewer-port WEB`` in a child process,
and the viewer's recording connects to it. Loopback by default (``viewer.serve_host``): a browser on
another host then goes through an SSH tunnel, or the rig names the interface to serve on.
"""

from __future__ import annotations

import atexit
import importlib.util
import os
import socket
import subprocess
import time
from pathlib import Path

from flagtrack.daemon.errors import ConfigError

ALL_INTERFACES = ("0.0.0.0", "::")


class RerunServer:
    """``rerun --serve-web`` bound to ``host`` (a child process, stopped by :meth:`close`).

    Raises:
        ConfigError: it did not start listening within ``start_timeout_s`` (a port in use, an
            address this host does not have), naming the viewer's keys.
    """

    def __init__(self, host: str, grpc_port: int, web_port: int, start_timeout_s: float = 30.0) -> None:
        self.host, self.grpc_port, self.web_port = host, grpc_port, web_port
        connect_host = "127.0.0.1" if host in ALL_INTERFACES else host
        self.url = f"rerun+http://{_url_host(connect_host)}:{grpc_port}/proxy"
        self.web_url = f"http://{_url_host(connect_host)}:{web_port}"
        command = [rerun_binary(), "--serve-web", "--bind", host, "--port", str(grpc_port),
                   "--web-viewer-port", str(web_port)]  # fmt: skip
        self._process = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        _RUNNING.add(self)
        deadline = time.monotonic() + start_timeout_s
        while not _accepts(connect_host, grpc_port):
            if self._process.poll() is not None or time.monotonic() > deadline:
                _, err = self.close()
                last = (err or "").strip().splitlines()[-1:] or ["did not start"]
                raise ConfigError(
                    f"the Rerun server on {host}:{grpc_port} (web {web_port}): {last[0][-300:]}",
                    key="viewer.serve_host",
                )
            time.sleep(0.05)

    def close(self) -> tuple[int | None, str]:
        """Stop the server (SIGTERM, then SIGKILL after 5 s); its exit code and what it wrote on stderr."""
        _RUNNING.discard(self)
        if self._process.poll() is None:
            self._process.terminate()
            try:
                _, err = self._process.communicate(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
                _, err = self._process.communicate()
        else:
            _, err = self._process.communicate()
        return self._process.returncode, err or ""


_RUNNING: set[RerunServer] = set()


@atexit.register
def _close_all() -> None:
    """A process that ends without closing its viewer leaves no server behind."""
    for server in list(_RUNNING):
        server.close()


def rerun_binary() -> str:
    """The ``rerun`` executable the rerun-sdk wheel carries (``RERUN_CLI_PATH`` if set), run directly:
    its Python wrapper (``python -m rerun_cli``) would leave it running when stopped.

    Raises:
        ConfigError: not found (rerun-sdk without its command-line part).
    """
    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return override
    spec = importlib.util.find_spec("rerun_cli")
    path = Path(spec.origin).parent / "rerun" if spec is not None and spec.origin else None
    if path is None or not path.exists():
        raise ConfigError("the rerun command-line server is not installed (rerun-sdk's rerun_cli)", key="viewer.sink")
    return str(path)


def _accepts(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host
