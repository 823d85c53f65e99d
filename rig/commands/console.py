"""`rig console`: serve the operator console (live view, scan, results, captures, calibration) to a browser.

Parsing and printing only: the app is :func:`rig.console.app.create_app`, served by uvicorn.
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import secrets
import sys
from pathlib import Path

from rig.commands._common import add_command
from rig.errors import ConfigError

LOOPBACK_HOSTS = ("localhost",)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "console",
        run,
        help="serve the operator console: run the scanner from a web browser",
        description="Start the operator console on the rig (the built-in simulated rig without --config) and print "
        "its URL: live camera view with saturation, histogram, focus and fringe modulation; exposure and projector "
        "controls; scan with progress and Stop; the height map, 3-D view and report; captures to reprocess and "
        "compare; the calibration wizard; device status. The JSON API is described at /api/docs. "
        "Binding beyond 127.0.0.1 requires an access token (one is generated and printed in the URL). "
        "Requests must name the console in their Host header (loopback names, --host, --allowed-host).",
    )
    parser.add_argument(
        "--config", type=Path, metavar="RIG.toml", help="rig config file (default: the built-in simulated rig)"
    )
    parser.add_argument(
        "--data",
        type=Path,
        default=Path("rig-data"),
        metavar="DIR",
        help="data directory for captures, results and calibrations (default ./rig-data; created)",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this computer only)"
    )
    parser.add_argument("--port", type=int, default=8765, help="port (default 8765; 0 picks a free one)")
    parser.add_argument(
        "--token",
        help="access token required from browsers and scripts, at least 16 characters (default: none on "
        "127.0.0.1, a generated one on any other address)",
    )
    parser.add_argument(
        "--allowed-host",
        action="append",
        default=[],
        metavar="NAME",
        help="another name browsers reach the console by (a reverse proxy's host name); repeatable",
    )


def is_loopback(host: str) -> bool:
    """Whether ``host`` only accepts connections from this computer."""
    if host in LOOPBACK_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from rig.config import load_config
    from rig.console.access import check_token
    from rig.console.app import create_app
    from rig.console.server import server_config

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port: expected 0 .. 65535, found {args.port}")
    if args.data.exists() and not args.data.is_dir():
        raise ConfigError(f"--data {args.data}: exists and is not a directory")
    token = args.token
    check_token(token)
    if token is None and not is_loopback(args.host):
        token = secrets.token_urlsafe(16)
    config = load_config(args.config)
    app = create_app(config, args.data, token=token, host=args.host, allowed_hosts=args.allowed_host)
    server = uvicorn.Server(server_config(app, args.host, args.port))

    async def announce() -> None:
        while not server.started:
            await asyncio.sleep(0.05)
        port = server.servers[0].sockets[0].getsockname()[1] if server.servers else args.port
        shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
        url = f"http://{shown if ':' not in shown else f'[{shown}]'}:{port}/" + (f"?token={token}" if token else "")
        print(f"rig console: {url}", flush=True)
        print(
            f"  rig: {config.source or 'built-in simulated rig'}; data: {args.data.resolve()}; Ctrl-C stops and closes the devices",
            flush=True,
        )

    async def serve() -> None:
        task = asyncio.create_task(announce())
        await server.serve()
        task.cancel()

    asyncio.run(serve())
    if not server.started:
        print(f"rig console: error: could not listen on {args.host}:{args.port}", file=sys.stderr)
        return 1
    return 0
