"""Memory of a training reference set: as a reconstruction holds clips (float64) against as a
training holds them (compact, :meth:`grip.core.reference.ReferenceClip.compact`).

Each way is loaded in a fresh process (so that one peak does not hide the other); it prints
the arrays' bytes, the resident memory after the load and its peak, and the load's seconds.
A run's own set can be above the 1 GiB one input may expand to: pass
``GRIP_LIMITS=max_total_bytes=...`` as a training run raises it for itself.

    GRIP_LIMITS=max_total_bytes=8000000000 python benchmarks/reference_memory.py \\
        --reference RUN/reference_train.npz [--json F]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

_CHILD = """
import json, resource, sys, time
import numpy as np
from grip.core.reference import ReferenceSet
t0 = time.perf_counter()
ref = ReferenceSet.load(sys.argv[1], compact=sys.argv[2] == "compact")
dt = time.perf_counter() - t0
arrays = sum(v.nbytes for c in ref.clips for v in vars(c).values() if isinstance(v, np.ndarray))
with open("/proc/self/statm") as f:
    rss = int(f.read().split()[1]) * resource.getpagesize()
print(json.dumps({"clips": len(ref), "frames": ref.total_frames, "array_gb": arrays / 1e9,
                  "rss_gb": rss / 1e9, "peak_rss_gb":
                  resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
                  "load_s": dt}))
"""


def measure(reference: str, how: str) -> dict:
    """One load of ``reference`` (``how``: ``"float64"`` or ``"compact"``) in a new process."""
    out = subprocess.run([sys.executable, "-c", _CHILD, reference, how], check=True,
                         capture_output=True, text=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reference", required=True, help="a reference set (RUN/reference_train.npz)")
    ap.add_argument("--json", type=Path, help="write the numbers here")
    args = ap.parse_args()
    rows = {how: measure(args.reference, how) for how in ("float64", "compact")}
    print(f"{args.reference}: {rows['float64']['clips']} clips, {rows['float64']['frames']} frames")
    print(f"{'held as':<9} {'arrays GB':>10} {'resident GB':>12} {'peak GB':>8} {'load s':>7}")
    for how, r in rows.items():
        print(f"{how:<9} {r['array_gb']:>10.2f} {r['rss_gb']:>12.2f} {r['peak_rss_gb']:>8.2f} "
              f"{r['load_s']:>7.1f}")  # fmt: skip
    ratio = rows["compact"]["peak_rss_gb"] / rows["float64"]["peak_rss_gb"]
    print(f"compact / float64 peak: {ratio:.2f}")
    if args.json:
        args.json.write_text(json.dumps({"reference": args.reference, **rows,
                                         "peak_ratio": ratio}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
