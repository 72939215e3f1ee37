"""The service's settings (:class:`ServeConfig`), checked before anything loads, and the check that
the optional ``serve`` extra is installed. Nothing here imports FastAPI or uvicorn."""
from __future__ import annotations

import importlib.util
import ipaddress
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..io import show_path
from ..config.params import DEFAULT_GRIPPER, DEFAULT_ROBOT
from ..piles.scene_file import DEFAULT_CELL as SCENE_DEFAULT_CELL
from ..geometry.units import UNIT_CHOICES

#: where ``--token`` is read from when not given on the command line (a command line is visible to
#: every user of the machine in ``ps``; the environment is not)
TOKEN_ENV = "GRASPLAN_TOKEN"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
DEFAULT_CELL = SCENE_DEFAULT_CELL  # a pick service plans in a bin unless told otherwise
#: request bodies larger than this are refused with 413 before they are read (bytes)
DEFAULT_MAX_BODY = 10 * 1024 * 1024
#: seconds a request may take, waiting in the queue included (then 503 waiting, 504 planning)
DEFAULT_TIME_LIMIT_S = 60.0
#: requests waiting for a worker's planner beyond this are refused at once with 503
DEFAULT_MAX_QUEUE = 64
MAX_WORKERS = 64
#: seconds from a connection's opening (or its previous response) to its next request's complete
#: headers; a connection idle or sending its headers slower is closed (408 when it had begun)
DEFAULT_HEADER_TIMEOUT_S = 5.0
#: seconds a request body may pause between two of its bytes before the connection is closed (408)
DEFAULT_BODY_TIMEOUT_S = 5.0
#: open connections from one client address; a new one beyond it replaces that address's oldest idle one
DEFAULT_MAX_CONNECTIONS_PER_CLIENT = 32
#: open connections in all; a new one beyond it replaces the oldest idle one
DEFAULT_MAX_CONNECTIONS = 1024
#: ``grasplan serve`` without ``--workers``: one planner process per core, at most this many
MAX_AUTO_WORKERS = 4
#: the packages of the ``serve`` extra (pyproject.toml)
SERVE_PACKAGES = ("fastapi", "uvicorn")
SERVE_EXTRA_HINT = "install the serve extra: pip install 'grasplan[serve]' (fastapi, uvicorn)"
_SIZE_RE = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*([kKmMgG]?)i?[bB]?\s*$")
_SIZE_UNITS = {"": 1, "k": 1024, "m": 1024**2, "g": 1024**3}


def missing_serve_packages() -> list[str]:
    """The packages of the ``serve`` extra that are not installed (empty: the service can run)."""
    return [p for p in SERVE_PACKAGES if importlib.util.find_spec(p) is None]


def require_serve_packages() -> None:
    """InputError (exit 3) naming the extra when FastAPI or uvicorn is missing."""
    missing = missing_serve_packages()
    if missing:
        raise InputError(f"grasplan serve needs {', '.join(missing)}, which is not installed; {SERVE_EXTRA_HINT}")


def parse_size(value: str | int, name: str = "--max-body") -> int:
    """A byte count: ``10485760``, ``10MB``, ``512k`` (binary multiples: 1k = 1024 bytes)."""
    if isinstance(value, bool):
        raise InputError(f"{name}: expected a size in bytes (e.g. 10MB), got {value!r}")
    if isinstance(value, int):
        n = value
    else:
        m = _SIZE_RE.match(str(value))
        if not m:
            raise InputError(f"{name}: cannot read {str(value)[:40]!r} as a size; write bytes or with a k, MB or "
                             "GB suffix, e.g. 10MB")
        x = float(m.group(1)) * _SIZE_UNITS[m.group(2).lower()]
        n = int(x) if math.isfinite(x) and x < 2**40 else 2**40
    if not 1024 <= n <= 2**31:
        raise InputError(f"{name}: expected a size between 1k and 2GB, got {value!r}")
    return n


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True, kw_only=True)
class ServeConfig:
    """What ``grasplan serve`` was started with (the options of the same names; docs/serve.md).

    ``parts_dir``: the folder of the part meshes (a part's name is its file's stem); ``robot``,
    ``gripper``, ``cell``: names or YAML paths (given by whoever starts the service, never by a
    client); ``units``: of every mesh in ``parts_dir``; ``token``: the bearer token every request
    but ``/health`` and the docs must carry (None: none required); ``max_body``: bytes;
    ``time_limit_s``: per request, queue included; ``workers``: planners, each with its own warm
    state (1: a thread of the HTTP process; N > 1: N planner processes); ``max_queue``: requests
    waiting for a planner before 503; ``header_timeout_s``, ``body_timeout_s``,
    ``max_connections``, ``max_connections_per_client``: what an HTTP connection may hold (idle or
    slow connections are closed; :mod:`grasplan.serve.protocol`);
    ``databases``: compute or load the grasp databases (and the picker) at start; ``config_dirs``:
    looked in first for robot, gripper and cell names (``--config-dir``)."""

    parts_dir: Path
    robot: str = DEFAULT_ROBOT
    gripper: str = DEFAULT_GRIPPER
    cell: str = DEFAULT_CELL
    units: str = "auto"
    token: str | None = field(default=None, repr=False)
    max_body: int = DEFAULT_MAX_BODY
    time_limit_s: float = DEFAULT_TIME_LIMIT_S
    workers: int = 1
    max_queue: int = DEFAULT_MAX_QUEUE
    header_timeout_s: float = DEFAULT_HEADER_TIMEOUT_S
    body_timeout_s: float = DEFAULT_BODY_TIMEOUT_S
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    max_connections_per_client: int = DEFAULT_MAX_CONNECTIONS_PER_CLIENT
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    databases: bool = True
    config_dirs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "parts_dir", Path(self.parts_dir).expanduser())
        try:
            is_dir = self.parts_dir.is_dir()
        except (OSError, ValueError):  # a name too long for the file system, a NUL
            is_dir = False
        if not is_dir:
            raise InputError(f"--parts {show_path(self.parts_dir)}: not a folder; give the folder of the part meshes "
                             "(a part's name is its file's stem)")
        if self.units not in UNIT_CHOICES:
            raise InputError(f"--units: {self.units!r} is not one of {', '.join(UNIT_CHOICES)}")
        if self.token is not None:
            if not self.token or len(self.token) < 8 or len(self.token) > 4096 or not self.token.isprintable() \
                    or " " in self.token:
                raise InputError(f"--token / ${TOKEN_ENV}: expected 8-4096 printable characters without spaces")
        parse_size(self.max_body)
        for name, t, hi in (("--time-limit", self.time_limit_s, 3600), ("--header-timeout", self.header_timeout_s, 600),
                            ("--body-timeout", self.body_timeout_s, 600)):
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or not 0 < t <= hi:
                raise InputError(f"{name}: expected seconds in (0, {hi}], got {t!r}")
        for name, v, hi in (("--workers", self.workers, MAX_WORKERS), ("--max-queue", self.max_queue, 100000),
                            ("--max-connections", self.max_connections, 1_000_000),
                            ("--max-connections-per-client", self.max_connections_per_client, 1_000_000),
                            ("--port", self.port, 65535)):
            if isinstance(v, bool) or not isinstance(v, int) or not (0 if name == "--port" else 1) <= v <= hi:
                raise InputError(f"{name}: expected a whole number in [{0 if name == '--port' else 1}, {hi}], "
                                 f"got {v!r}")
        if self.max_connections_per_client > self.max_connections:
            raise InputError(f"--max-connections-per-client: {self.max_connections_per_client} is more than "
                             f"--max-connections {self.max_connections}; give at most {self.max_connections}")
        object.__setattr__(self, "config_dirs", tuple(str(d) for d in self.config_dirs))
        if not self.host or len(self.host) > 255:
            raise InputError(f"--host: expected a host name or address, got {self.host!r}")

    @property
    def requires_token(self) -> bool:
        return self.token is not None

    def bind_warning(self) -> str | None:
        """A warning when the service listens beyond this machine without a token."""
        if is_loopback(self.host) or self.token is not None:
            return None
        return (f"--host {self.host} accepts connections from other machines and no --token is set: anyone who can "
                f"reach port {self.port} can plan with this service; set --token or ${TOKEN_ENV}")


def token_from_env(token: str | None) -> str | None:
    """``--token`` or, when not given, ``$GRASPLAN_TOKEN`` (an empty variable means none)."""
    if token is not None:
        return token
    env = os.environ.get(TOKEN_ENV)
    return env if env else None


def config_to_json(config: ServeConfig) -> dict:
    """The settings as JSON (how the planner processes of ``--workers N`` receive them)."""
    from dataclasses import fields

    d = {f.name: getattr(config, f.name) for f in fields(config)}
    d["parts_dir"] = str(config.parts_dir)
    d["config_dirs"] = list(config.config_dirs)
    return d


def config_from_json(d: dict) -> ServeConfig:
    return ServeConfig(**{**d, "parts_dir": Path(d["parts_dir"]), "config_dirs": tuple(d.get("config_dirs", ()))})
