"""Pack captured plans into a directory laid out like ptx/ (plans/manifest.json + plans/*.wrp.zst).

    python kernels_py/pack_plans.py --capture WORK --out ptx --packer target/release/instantmimic

WORK is capture.py's output. Each raw plan is packed by `instantmimic plan pack` (zero initial
bytes dropped, our PlanInfo section added, zstd), and the manifest is rewritten to list the packed
files. Plans whose world count is in --raw are copied uncompressed instead (packing a 16384-world
plan at zstd level 19 takes minutes; a raw plan loads the same).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import subprocess
import sys
import tempfile



def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--capture", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--packer", required=True, help="the instantmimic binary")
    parser.add_argument("--raw", type=int, nargs="*", default=[], help="world counts to copy unpacked")
    parser.add_argument("--only", type=int, nargs="*", help="keep only these world counts")
    args = parser.parse_args(argv)

    cap = pathlib.Path(args.capture)
    out = pathlib.Path(args.out)
    manifest = json.loads((cap / "manifest.json").read_text())
    plans_dir = out / "plans"
    plans_dir.mkdir(parents=True, exist_ok=True)
    kept = []
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(manifest["physics"], f)
        physics_json = f.name
    for plan in manifest["plans"]:
        if args.only and plan["nworld"] not in args.only:
            continue
        raw = cap / plan.pop("raw")
        if plan["nworld"] in args.raw:
            plan["file"] = raw.name
            shutil.copyfile(raw, plans_dir / raw.name)
        else:
            cmd = [args.packer, "plan", "pack", str(raw), "-o", str(plans_dir / plan["file"]),
                   "--name", plan["name"], "--nworld", str(plan["nworld"]), "--physics", physics_json]
            subprocess.run(cmd, check=True)
        kept.append(plan)
    manifest["plans"] = kept
    (plans_dir / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    print(f"packed {len(kept)} plans into {plans_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
