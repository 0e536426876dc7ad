"""``tltrack router``: a Zenoh router, an operator's in the federated topology."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tltrack.app.access import ManifestOption, manifest_or_exit
from tltrack.app.common import app, refused, say_error


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
            "`source/<id>`, as the operator manifest lists them): its ACL and dictionary, dialling "
            "as `router-<operator>`"
        ),
    ] = None,
    manifest: ManifestOption = None,
) -> None:
    """Run a Zenoh router (the Python package in router mode) until Ctrl-C or SIGTERM.

    Example: `tltrack router --listen tcp/0.0.0.0:7447`; the primary's router of the federated
    topology: `tltrack router --operator primary --listen tcp/0.0.0.0:7447 --connect
    tls/referee.example.org:7448`. The environment (TLTRACK_ZENOH_*) overrides what --operator sets.
    """
    import os
    import tempfile

    import zenoh

    from tltrack.live import access
    from tltrack.live.manifest import ManifestError
    from tltrack.live.router import router_settings, run_router
    from tltrack.wire.transport import ZenohSettings, refusal

    with tempfile.TemporaryDirectory(prefix="tltrack-router-") as tmp:
        if operator is not None:
            try:
                env = access.router_env(manifest_or_exit(manifest), operator, Path(tmp))
            except ManifestError as err:
                say_error(f"--operator: {err}")
                raise typer.Exit(2) from None
            for name, value in env.items():
                os.environ.setdefault(name, value)
        listen = listen or ["tcp/0.0.0.0:7447"]
        try:
            settings = router_settings(listen, ZenohSettings(), connect)
        except ValueError as err:  # TLTRACK_ZENOH_*, --listen, --connect
            raise refused(err) from None
        try:
            run_router(listen, settings, connect=connect)
        except zenoh.ZError as err:  # a port in use, a certificate zenoh cannot read
            say_error(f"the router did not start on {', '.join(listen)}: {refusal(err)}")
            raise typer.Exit(1) from None
