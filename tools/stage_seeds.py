"""The stages' mirrored share and filter MPJPE per simulator seed, with the true calibration.

Two columns of ``hiros bench robust --seeds ...`` (the true calibration only), quicker to read
when only the tracker's facing changed: a change there moves single seeds by whole points, so
its figures in docs/stages-robustness.md are over several seeds, each row as
``hiros_bench.robust.measure`` runs it (60 s, default settings):

    .venv/bin/python tools/stage_seeds.py exercise-on-spot 0-7
    .venv/bin/python tools/stage_seeds.py noisy-sdk 0,1,4,5,6,7,8,9
"""

from __future__ import annotations

import sys

import numpy as np

from hiros_bench.robust import measure
from hiros_bench.seeds import parse_seeds


def main(argv: list[str]) -> int:
    """Print each seed's mirrored share and filter MPJPE, then their means."""
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    condition, seeds = argv[0], parse_seeds(argv[1])
    mirrored, errors = [], []
    for seed in seeds:
        row = measure(condition, seed=seed)
        mirrored.append(row.mirrored)
        errors.append(row.mpjpe["filter"])
        print(f"{condition} seed {seed}: mirrored {100 * row.mirrored:.2f} %, "
              f"filter {1e3 * row.mpjpe['filter']:.1f} mm", flush=True)  # fmt: skip
    print(f"{condition} seeds {argv[1]}: mirrored {100 * np.mean(mirrored):.2f} %, "
          f"filter {1e3 * np.mean(errors):.1f} mm")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
