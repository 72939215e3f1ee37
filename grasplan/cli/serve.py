"""``grasplan serve --parts DIR``: an HTTP JSON service holding a warm planner (docs/serve.md)."""
from __future__ import annotations

import logging

import click

from ..config.params import DEFAULT_GRIPPER
from ..serve.config import (
    DEFAULT_BODY_TIMEOUT_S,
    DEFAULT_CELL,
    DEFAULT_HEADER_TIMEOUT_S,
    DEFAULT_HOST,
    DEFAULT_MAX_CONNECTIONS,
    DEFAULT_MAX_CONNECTIONS_PER_CLIENT,
    DEFAULT_MAX_BODY,
    DEFAULT_MAX_QUEUE,
    DEFAULT_PORT,
    DEFAULT_TIME_LIMIT_S,
    MAX_AUTO_WORKERS,
    TOKEN_ENV,
)
from .common import info, units_option
from .options import FLOAT, INT, config_dir_option, robot_option


@click.command(name="serve")
@click.option("--parts", "parts_dir", required=True, type=click.Path(file_okay=False),
              help="Folder of the part meshes a request may name; a part's name is its file's stem "
                   "(TLess20.stl -> TLess20), as `scene drop` and `clutter` name it. Not searched recursively.")
@click.option("--host", default=DEFAULT_HOST, show_default=True,
              help="Address to listen on. The default accepts this machine only; 0.0.0.0 accepts the network "
                   "(then set --token).")
@click.option("--port", type=INT, default=DEFAULT_PORT, show_default=True, help="TCP port.")
@robot_option
@click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True,
              help="Gripper name (see --config-dir) or path to a gripper YAML.")
@click.option("--cell", default=DEFAULT_CELL, show_default=True,
              help="Cell name (see --config-dir) or path to a cell YAML: the cell of every plan and pick.")
@units_option
@config_dir_option
@click.option("--token", default=None,
              help=f"Require 'Authorization: Bearer TOKEN' on every request but /health and /docs (compared in "
                   f"constant time). Default: ${TOKEN_ENV}, else none. Prefer the variable: a command line is "
                   "visible to every user of the machine.")
@click.option("--max-body", default=str(DEFAULT_MAX_BODY), show_default="10MB",
              help="Largest request body (bytes, or with k, MB, GB); larger ones get 413 before they are read.")
@click.option("--time-limit", "time_limit_s", type=FLOAT, default=DEFAULT_TIME_LIMIT_S, show_default=True,
              help="Seconds a request may take, queueing included: 503 when it could not start in time, 504 when "
                   "its planning ran past it.")
@click.option("--workers", type=INT, default=None, show_default=f"one per core, at most {MAX_AUTO_WORKERS}",
              help="Planner processes, each with its own warm state and one request at a time; each request goes "
                   "to a free one, and one past --time-limit is stopped.")
@click.option("--max-queue", type=INT, default=DEFAULT_MAX_QUEUE, show_default=True,
              help="Requests waiting for a free planner beyond this are refused at once with 503.")
@click.option("--header-timeout", "header_timeout_s", type=FLOAT, default=DEFAULT_HEADER_TIMEOUT_S,
              show_default=True,
              help="Seconds a connection may take to send a request's headers, from its opening or its previous "
                   "response; an idle connection is closed after it (408 when a request had begun).")
@click.option("--body-timeout", "body_timeout_s", type=FLOAT, default=DEFAULT_BODY_TIMEOUT_S, show_default=True,
              help="Seconds a request body may pause; the whole body must arrive within --time-limit (else 408).")
@click.option("--max-connections-per-client", type=INT, default=DEFAULT_MAX_CONNECTIONS_PER_CLIENT,
              show_default=True,
              help="Open connections from one client address; a new one beyond it replaces that address's oldest "
                   "idle connection, or is refused (503) when all are busy with requests.")
@click.option("--max-connections", type=INT, default=DEFAULT_MAX_CONNECTIONS, show_default=True,
              help="Open connections in all (likewise); the open-file limit is raised to fit them.")
@click.option("--pick/--no-pick", "databases", default=True, show_default=True,
              help="Compute or load every part's grasp database at start for POST /pick (--no-pick: /plan and "
                   "/export only, a faster start).")
def command(parts_dir, host, port, robot, gripper, cell, units, config_dir, token, max_body, time_limit_s,
            workers, max_queue, header_timeout_s, body_timeout_s, max_connections_per_client, max_connections,
            databases):
    """Serve picks, plans and robot programs over HTTP (JSON) from a warm planner.

    \b
    POST /pick    a grasplan.scene/1 document (+ options {max_picks, seed}) -> grasplan.picks/1
    POST /plan    {"part": NAME, "options": {...}} -> grasplan.plan/1
    POST /export  {"document": PLAN, "format": NAME} -> the program text
    GET  /health, /robots, /grippers, /parts; OpenAPI at /docs

    Parts are named, never given as paths: a request can only use the meshes in --parts. Needs the
    serve extra (pip install 'grasplan[serve]'). Stop with Ctrl-C or SIGTERM: the requests in
    progress are answered, then it exits 0.

    \b
    Example:
      GRASPLAN_TOKEN=s3cret-token grasplan serve --parts parts/ --cell bin
      curl -H 'Authorization: Bearer s3cret-token' localhost:8765/parts
    """
    from ..serve.config import ServeConfig, parse_size, require_serve_packages, token_from_env
    from ..serve.run import default_workers, serve

    require_serve_packages()
    if workers is None:
        workers = default_workers()
    config = ServeConfig(parts_dir=parts_dir, robot=robot, gripper=gripper, cell=cell, units=units,
                         token=token_from_env(token), max_body=parse_size(max_body), time_limit_s=time_limit_s,
                         workers=workers, max_queue=max_queue, header_timeout_s=header_timeout_s,
                         body_timeout_s=body_timeout_s, max_connections=max_connections,
                         max_connections_per_client=max_connections_per_client, host=host, port=port,
                         databases=databases, config_dirs=tuple(config_dir))
    logging.basicConfig(level=logging.INFO, format="grasplan serve: %(message)s")
    warning = config.bind_warning()
    if warning:
        info(f"grasplan: warning: {warning}")
    info(f"grasplan serve: starting (parts {parts_dir}, robot {robot}, gripper {gripper}, cell {cell}; "
         f"token {'required' if config.requires_token else 'not required'}; {workers} "
         f"planner{'s' if workers > 1 else ''})")
    serve(config, lambda line: info(f"grasplan serve: {line}"))
