"""The low-mode chain car's identified lash against its damping ratio and the logging rate.

The same drives of the independent generator (``bench/indep``, the ``chain_low`` car with its lash
right, 1.3x or 0.75x the file's, and its damping set to a damping ratio) recorded at several rates,
each identified on drive A as ``bench/identify_indep.py`` does. Printed per drive: the identified
total lash over the truth with its 90 % interval, and the parameters named. Development seeds
(990 000 on): not a scored set.

    .venv/bin/python bench/lash_damping.py --drives 6                       # damping ratio drawn in 0.3-0.55
    .venv/bin/python bench/lash_damping.py --drives 6 --zeta 0.12 --rates 200
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench.identify_indep import identify  # noqa: E402
from bench.indep.cases import CHAIN_LOW_ZETA, Case, _chain_damping, build  # noqa: E402

OUT = REPO / "bench" / "out" / "lash_damping"
SEED0 = 990_000
GAPS = (1.0, 1.3, 0.75)  # the lash's truth over the file's, by drive


def one(job: tuple[int, float, float, float]) -> str:
    seed, rate, gap, zeta = job
    base = {"gap_scale": gap}
    base["c_scale"] = _chain_damping(base, zeta, "chain_low")
    folder = OUT / f"zeta{zeta:.3f}"
    folder.mkdir(parents=True, exist_ok=True)
    case = build(Case(f"lash_{seed}_{rate:g}hz", "base", seed, {}, ["base_parameters"], 60.0, car="chain_low",
                      base=base, rate_hz=rate, recorded={"target_zeta": zeta}), folder)
    idn = identify(case, folder)
    head = f"seed {seed}  {rate:6.0f} Hz  lash {gap:4.2f}x file  damping ratio {zeta:.3f}:"
    if idn is None or idn.error:
        return f"{head} {getattr(idn, 'error', 'app.identify unavailable')}"
    value, lo, hi = (x / case.truth["lash_mrad"] for x in idn.params["lash"])
    interval = f"[{lo:.3f}, {hi:.3f}]" if np.isfinite(lo) else "(not identified: kept at the file's)"
    return f"{head} identified/truth {value:.3f} {interval}  named {', '.join(idn.named) or '-'}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--drives", type=int, default=6)
    ap.add_argument("--zeta", type=float, default=None, help="damping ratio of every drive (default: drawn)")
    ap.add_argument("--rates", default="50,200,1000", help="logging rates (Hz), comma-separated")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    jobs = []
    for k in range(args.drives):
        seed = SEED0 + k
        zeta = args.zeta if args.zeta is not None else float(np.random.default_rng(seed).uniform(*CHAIN_LOW_ZETA))
        jobs += [(seed, float(rate), GAPS[k % len(GAPS)], zeta) for rate in args.rates.split(",")]
    with ProcessPoolExecutor(args.jobs) as pool:
        for line in pool.map(one, jobs):
            print(line, flush=True)


if __name__ == "__main__":
    main()
