"""``tltrack link``: the link emulator between two routers (:mod:`tltrack.live.link`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from tltrack.app.common import app, console, say_error


@app.command()
def link(
    to: Annotated[str, typer.Option(help="the router to relay to: tcp/HOST:PORT")],
    listen: Annotated[
        str, typer.Option(help="where to listen, HOST:PORT (dial this instead of --to)")
    ] = "127.0.0.1:7450",
    delay_ms: Annotated[float, typer.Option(help="delay each way, up to an hour")] = 0.0,
    jitter_ms: Annotated[float, typer.Option(help="± uniform on the delay")] = 0.0,
    rate_kbps: Annotated[
        float | None, typer.Option(help="bandwidth cap each way (kbit/s, > 0)")
    ] = None,
    control: Annotated[
        Path | None,
        typer.Option(
            help="a JSON file reread when it changes: any of delay_ms, jitter_ms, rate_kbps, "
            "stalled, cut"
        ),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="seed of the jitter")] = None,
) -> None:
    """Relay TCP from --listen to --to with delay, jitter and a bandwidth cap; stall or cut it
    while it runs by writing the --control file. Until Ctrl-C or SIGTERM.

    Example: `tltrack link --to tcp/127.0.0.1:7448 --listen 127.0.0.1:7450 --delay-ms 100
    --jitter-ms 20 --control link.json`, the source's router dialling tcp/127.0.0.1:7450; then
    `echo '{"cut": true}' > link.json` cuts the link and `echo '{"cut": false}' > link.json`
    restores it.
    """
    import time

    from tltrack.live import supervisor
    from tltrack.live.link import (
        LinkEmulator,
        Shape,
        apply_control,
        check_setting,
        host_port,
        read_control,
    )

    try:
        for name, value in (("delay_ms", delay_ms), ("jitter_ms", jitter_ms)):
            check_setting(name, value, "--" + name.replace("_", "-"))
        if rate_kbps is not None:
            check_setting("rate_kbps", rate_kbps, "--rate-kbps")
        host_port(to, "--to")
        address = host_port(listen, "--listen", listen=True)
        rate = None if rate_kbps is None else rate_kbps * 1e3
        shape = Shape(delay_ms / 1e3, jitter_ms / 1e3, rate)
        emulator = LinkEmulator(to, address, shape=shape, seed=seed)
    except (ValueError, OSError) as err:
        say_error(str(err))
        raise typer.Exit(2) from None
    console.print(f"link {emulator.endpoint} -> {to}: {shape}")
    seen: float | None = None
    with supervisor.stop_on_signals(), emulator:
        try:
            while True:
                if control is not None and control.exists():
                    mtime = control.stat().st_mtime
                    if mtime != seen:
                        seen = mtime
                        try:
                            apply_control(emulator, read_control(control))
                        except ValueError as err:
                            console.print(f"[red]control ignored:[/red] {escape(str(err))}")
                        else:
                            state = "cut" if emulator.is_cut else emulator.shapes()["forward"]
                            console.print(f"link now: {state}")
                time.sleep(0.2)
        except supervisor.Interrupted:
            console.print("link: stopped")
