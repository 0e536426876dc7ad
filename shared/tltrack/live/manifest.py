"""The operator manifest: which operators a deployment has, and who each one is on the wire.

Every operator has a role, an operator path in the keys (:mod:`tltrack.wire.keys`), the
identities its services log in under (usernames, or certificate common names with mutual TLS),
and a router of its own in the federated topology, which dials other routers under
``router-<name>``:

==========  ===============  =============================  =====================
role        operator path    identities (services)          router identity
==========  ===============  =============================  =====================
referee     ``referee``      sensor (sensor_sim), referee   (dialled by all)
                             (scorer), dashboard
primary     ``primary``      primary (primary_tracker,      ``router-primary``
                             its sensor)
source      ``source/<id>``  ``source-<id>`` (its tracker,  ``router-source-<id>``
                             its sensor)
==========  ===============  =============================  =====================

The referee and the primary are always there; the manifest lists the source operators
(``shared/tltrack/access/operators.toml``; another file from ``--manifest`` or
``TLTRACK_MANIFEST``). The access files, the demo's stack and compose.yaml follow from it
(:mod:`tltrack.live.access`).
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from tltrack.config import describe_validation_error
from tltrack.wire import keys

#: the environment variable naming another manifest
ENV = "TLTRACK_MANIFEST"
#: the package's manifest
DEFAULT = Path(__file__).resolve().parents[1] / "access" / "operators.toml"
#: the referee's services and the identity each logs in under
REFEREE_SERVICES = {"sensor_sim": "sensor", "scorer": "referee", "dashboard": "dashboard"}


class ManifestError(ValueError):
    """A manifest was refused; the message names the file and the field."""


class SourceOperator(BaseModel):
    """One source operator."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    id: str = Field(pattern=r"^[A-Za-z0-9_-]{1,32}$", description="its id in configs and keys")
    compose_profile: str | None = Field(
        None, pattern=r"^[a-z0-9-]{1,40}$", description="compose starts it only with this profile"
    )


@dataclass(frozen=True)
class Operator:
    """An operator as the wire knows it (see the module's table)."""

    role: str
    path: str  #: its segment of the keys: referee, primary, source/<id>
    identities: tuple[str, ...]
    router: str  #: its router's name: referee, primary, source-<id>

    @property
    def router_identity(self) -> str | None:
        """The identity its router dials others under (the referee's dials nobody)."""
        return None if self.role == "referee" else f"router-{self.router}"


def _folded(source_id: str) -> str:
    return source_id.lower().replace("-", "_")


class Manifest(BaseModel):
    """The source operators of a deployment (the referee and the primary are implied)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    sources: list[SourceOperator] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique(self) -> Manifest:
        ids = [s.id for s in self.sources]
        if len(set(ids)) != len(ids):
            raise ValueError(f"sources: an id appears twice in {ids}")
        # a password variable (TLTRACK_PASSWORD_SOURCE_S_1) and a host name are blind to case
        # and to - against _: two ids they cannot tell apart would share them
        alike = [i for i in ids if [_folded(j) for j in ids].count(_folded(i)) > 1]
        if alike:
            raise ValueError(f"sources: {alike} differ only in case or in - against _")
        return self

    @property
    def source_ids(self) -> list[str]:
        return [s.id for s in self.sources]

    @property
    def operators(self) -> list[Operator]:
        """The referee, the primary, then every source, in the manifest's order."""
        return [
            Operator("referee", keys.REFEREE, tuple(REFEREE_SERVICES.values()), keys.REFEREE),
            Operator("primary", keys.PRIMARY, (keys.PRIMARY,), keys.PRIMARY),
            *(
                Operator("source", keys.source_operator(s), (f"source-{s}",), f"source-{s}")
                for s in self.source_ids
            ),
        ]

    def operator(self, path: str) -> Operator:
        """The operator of path ``path`` (``referee``, ``primary``, ``source/<id>``)."""
        for op in self.operators:
            if op.path == path:
                return op
        known = ", ".join(op.path for op in self.operators)
        raise ManifestError(f"operator {path!r} is not in the manifest; it lists {known}")

    @property
    def identities(self) -> list[str]:
        """Every service identity."""
        return [i for op in self.operators for i in op.identities]

    @property
    def router_identities(self) -> list[str]:
        """Every router that dials another: router-primary, router-source-<id>..."""
        return [r for op in self.operators if (r := op.router_identity) is not None]

    @staticmethod
    def password(identity: str) -> str:
        """The demo password of ``identity``. A deployment gives its own dictionary instead
        (TLTRACK_ZENOH_USRPWD_DICTIONARY_FILE), as deploy/zenoh/README.md says."""
        return f"demo-{identity}-pw"

    def tracker_service(self, source_id: str) -> str:
        """The process (and compose service) name of a source's tracker: the first source's is
        ``source_tracker``, another's ``source_tracker_<id>``."""
        return (
            "source_tracker" if source_id == self.source_ids[0] else f"source_tracker_{source_id}"
        )


def load_manifest(path: str | Path | None = None) -> Manifest:
    """The manifest at ``path``, else at ``$TLTRACK_MANIFEST``, else the package's; a
    :class:`ManifestError` names the file and the problem."""
    where = Path(path or os.environ.get(ENV) or DEFAULT)
    try:
        data = tomllib.loads(where.read_text())
    except OSError as err:
        raise ManifestError(f"cannot read the operator manifest {where}: {err.strerror}") from None
    except UnicodeDecodeError:
        raise ManifestError(f"{where}: not UTF-8 text (a manifest is TOML)") from None
    except tomllib.TOMLDecodeError as err:
        raise ManifestError(f"{where}: not valid TOML: {err}") from None
    except RecursionError:
        raise ManifestError(f"{where}: not valid TOML: nested too deeply") from None
    try:
        return Manifest.model_validate(data)
    except ValidationError as err:
        raise ManifestError(f"{where}: {describe_validation_error(err)}") from None
