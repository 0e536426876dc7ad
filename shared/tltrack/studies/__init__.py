"""Studies beyond the paper, one per module, each a markdown report, its numbers and a figure:

- :mod:`~.robust`: robust transfer against honest, biased, diverged and stale sources;
- :mod:`~.sources`: several source operators, honest or with a biased one among them;
- :mod:`~.budget`: RMSE against the share of steps that use a transfer;
- :mod:`~.heterogeneous`: operators with different sensors;
- :mod:`~.presets`: lost tracks and the paired claims in every preset and truth mode;
- :mod:`~.intensities`: TL against isolated at every primary intensity;
- :mod:`~.realizations`: the paper's trajectory as a measured distribution;
- :mod:`~.manoeuvres`: one motion model against a target class's modes, on manoeuvring targets;
- :mod:`~.clutter`: the lost share against the false alarms in the gate, at several pd;
- :mod:`~.links`: RMSE and lost share on vehicles: lossy, late links, own rates and clocks.

:mod:`~.common` holds what they share: a :class:`~.common.Setting` (runs, seed, filter kind,
base configuration), a :class:`~.common.Runner` (how the engine runs) and paired differences.
"""

from tltrack.studies.budget import budget
from tltrack.studies.clutter import SWEEPS as CLUTTER_SWEEPS
from tltrack.studies.clutter import clutter
from tltrack.studies.common import Runner, Setting
from tltrack.studies.heterogeneous import heterogeneous
from tltrack.studies.intensities import intensities
from tltrack.studies.links import cell_names as link_cells
from tltrack.studies.links import links
from tltrack.studies.manoeuvres import CONFIGS as MANOEUVRE_CONFIGS
from tltrack.studies.manoeuvres import manoeuvres
from tltrack.studies.presets import presets
from tltrack.studies.realizations import realizations
from tltrack.studies.robust import robust
from tltrack.studies.sources import sources

__all__ = [
    "CLUTTER_SWEEPS",
    "MANOEUVRE_CONFIGS",
    "Runner",
    "Setting",
    "budget",
    "clutter",
    "heterogeneous",
    "intensities",
    "link_cells",
    "links",
    "manoeuvres",
    "presets",
    "realizations",
    "robust",
    "sources",
]
