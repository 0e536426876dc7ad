"""``tltrack router``: a Zenoh router, an operator's in the federated topology."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tltrack.app.common import (
    app,
    console,
)


@app.command()
def router(
    listen: Annotated[list[str] | None, typer.Option(help="endpoint(s) to listen on")] = None,
    connect: Annotated[
        list[str] | None, typer.Option(help="other routers to dial (redialled when lost)")
    ] = None,
    operator: Annotated[
        str | None,
        typer.Option(
            help="be this operator's router of the federated topology (referee, primary, "
            "source/<id>): the package's ACL and dictionary for it, dialling as router-<operator>"
        ),
    ] = None,
) -> None:
    """Run a Zenoh router (the Python package in router mode) until Ctrl-C or SIGTERM.

    Example: `tltrack router --listen tcp/0.0.0.0:7447`; the primary's router of the federated
    topology: `tltrack router --operator primary --listen tcp/0.0.0.0:7447 --connect
    tls/referee.example.org:7448`. The environment (TLTRACK_ZENOH_*) overrides what --operator sets.
    """
    import os
    import tempfile

    from tltrack.live import topology
    from tltrack.live.router import run_router
    from tltrack.wire import keys
    from tltrack.wire.transport import ZenohSettings

    if operator is not None and not (
        operator in (keys.REFEREE, keys.PRIMARY)
        or f"router-{operator.replace('/', '-')}" in topology.all_passwords()
    ):
        console.print(f"[red]error:[/red] --operator: unknown operator {operator!r}")
        raise typer.Exit(2)
    with tempfile.TemporaryDirectory(prefix="tltrack-router-") as tmp:
        if operator is not None:
            for name, value in topology.access_env(operator, Path(tmp)).items():
                os.environ.setdefault(name, value)
        run_router(listen or ["tcp/0.0.0.0:7447"], ZenohSettings(), connect=connect)
