"""``tltrack access``: the operator manifest, and the access files that follow from it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tltrack.app.common import app, console, refused, say_error

if TYPE_CHECKING:
    from tltrack.live.manifest import Manifest

access_app = typer.Typer(help="The operator manifest and the access files that follow from it.")
app.add_typer(access_app, name="access")

#: ``--manifest``, shared by the commands that read the operator manifest
ManifestOption = Annotated[
    Path | None,
    typer.Option(
        "--manifest",
        envvar="TLTRACK_MANIFEST",
        help="the operator manifest (TOML; default: the package's access/operators.toml)",
    ),
]


def manifest_or_exit(path: Path | None) -> Manifest:
    """The manifest, or exit 2 with the reason."""
    from tltrack.live.manifest import ManifestError, load_manifest

    try:
        return load_manifest(path)
    except ManifestError as err:
        say_error(str(err))
        raise typer.Exit(2) from None


@access_app.command()
def show(manifest: ManifestOption = None) -> None:
    """Every operator of the manifest: its role, its identities and its router."""
    from rich.table import Table

    m = manifest_or_exit(manifest)
    t = Table(title="operators")
    for col in ("role", "operator", "identities", "router dials as"):
        t.add_column(col)
    for op in m.operators:
        t.add_row(op.role, op.path, ", ".join(op.identities), op.router_identity or "-")
    console.print(t)


@access_app.command()
def generate(
    manifest: ManifestOption = None,
    root: Annotated[Path, typer.Option(help="the repository to write into")] = Path("."),
    check: Annotated[bool, typer.Option(help="only say which files are out of date")] = False,
) -> None:
    """Write the repository's files that follow from the manifest: the package's access control
    and password files, and compose.yaml (from deploy/compose.template.yaml)."""
    from tltrack.live import access

    m = manifest_or_exit(manifest)
    if not (root / "deploy" / "compose.template.yaml").is_file():
        say_error(f"{root.resolve()} is not a tltrack repository")
        raise typer.Exit(2)
    out_of_date = access.stale(m, root)
    if check:
        for p in out_of_date:
            console.print(f"out of date: {p}")
        raise typer.Exit(1 if out_of_date else 0)
    files = access.repository_files(m, root)
    if missing := sorted({str(p.parent) for p in files if not p.parent.is_dir()}):
        # checked before any file is written: a half-written set would disagree with itself
        say_error(f"{root.resolve()} is not a tltrack repository (no {', '.join(missing)})")
        raise typer.Exit(2)
    for p, text in files.items():
        if p in out_of_date:
            p.write_text(text)
            console.print(f"wrote {p}")


@access_app.command(
    "zenoh-cli-config",
    epilog="Example:\n\n    tltrack access zenoh-cli-config --as primary --out primary.json5\n\n"
    "    zenoh --config primary.json5 subscribe -k 'tltrack/source/\\*/transfer/\\*' "
    "--decoder tltrack",
)
def zenoh_cli_config(
    operator: Annotated[
        str,
        typer.Option(
            "--as",
            help="the operator to log in as: referee, primary, `source/<id>` (the manifest's)",
        ),
    ],
    out: Annotated[
        Path | None, typer.Option(help="the file to write [`zenoh-cli-<operator>.json5`]")
    ] = None,
    endpoint: Annotated[
        str | None, typer.Option(help="the router to connect to [tcp/127.0.0.1:7447]")
    ] = None,
    identity: Annotated[
        str | None,
        typer.Option(help="which of the operator's identities (the referee has three) [its first]"),
    ] = None,
    manifest: ManifestOption = None,
) -> None:
    """Write a zenoh-cli `--config` file that connects to the router under an operator's
    identity, with its demo password (so the file is readable by its owner only).

    It is rendered from the services' own Zenoh settings (multicast scouting off, the same lease),
    so zenoh-cli sees the network as a service of that operator does: what the router's access
    control lets that identity read, and nothing else. TLS settings come from the environment
    (TLTRACK_ZENOH_TLS_ROOT_CA...), as for the services.
    """
    from tltrack.live import access
    from tltrack.live.manifest import ManifestError
    from tltrack.wire.transport import DEFAULT_ENDPOINT

    m = manifest_or_exit(manifest)
    try:
        settings = access.client_settings(m, operator, endpoint or DEFAULT_ENDPOINT, identity)
        text = access.zenoh_cli_config(settings, operator)
    except ManifestError as err:
        say_error(f"--as: {err}")
        raise typer.Exit(2) from None
    except ValueError as err:  # a setting zenoh or the settings' checks refuse
        raise refused(err) from None
    path = out or Path(f"zenoh-cli-{m.operator(operator).router}.json5")
    try:
        access.write_private(path, text)
    except OSError as err:
        say_error(f"cannot write {path}: {err.strerror}")
        raise typer.Exit(2) from None
    console.print(
        f"wrote {path} (mode 600): zenoh --config {path} subscribe -k KEY --decoder tltrack"
    )
