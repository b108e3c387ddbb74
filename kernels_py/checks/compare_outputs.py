"""Compare two runs of the CPU kernel checks (tests/env_kernels_cpu.rs) program by program.

    python kernels_py/checks/compare_outputs.py BEFORE_DIR AFTER_DIR

Each directory is a copy of `target/tmp/env_kernels_cpu/` after `cargo test --test
env_kernels_cpu` (one subdirectory per check, each with run_kernel.py's `spec.json`, input
`<buffer>.bin` and output `<buffer>.out.bin` files), e.g. BEFORE from an older commit's kernels
and AFTER from this one's. Programs are matched by name. For every buffer both runs have, with
the same input bytes, the outputs must be the same bytes; buffers only one run has (arguments a
change added or removed) are listed, and programs only one run has are counted. Exit status 1
when any output differs. Used to show that a kernel change leaves old cases' results bit for bit
(issue 19: the single clip as the library of one).
"""

from __future__ import annotations

import json
import pathlib
import sys


def programs(root: pathlib.Path) -> dict:
    found = {}
    for spec_path in sorted(root.glob("*/spec.json")):
        spec = json.loads(spec_path.read_text())
        for program in spec["programs"]:
            found[(spec_path.parent.name, program["name"])] = (spec_path.parent / program["dir"], program)
    return found


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    before, after = (programs(pathlib.Path(a)) for a in argv)
    differ = compared = buffers = 0
    only = {}
    for key in sorted(set(before) & set(after)):
        (dir_b, prog_b), (dir_a, prog_a) = before[key], after[key]
        names_b = {b["name"] for b in prog_b["buffers"]}
        names_a = {b["name"] for b in prog_a["buffers"]}
        for name in sorted(names_b ^ names_a):
            side = "before" if name in names_b else "after"
            only.setdefault((side, name), 0)
            only[(side, name)] += 1
        for name in sorted(names_b & names_a):
            inputs = [(d / f"{name}.bin").read_bytes() for d in (dir_b, dir_a)]
            if inputs[0] != inputs[1]:
                print(f"{key[0]}: {key[1]}: {name}: the inputs differ (not compared)")
                continue
            outputs = [(d / f"{name}.out.bin").read_bytes() for d in (dir_b, dir_a)]
            buffers += 1
            if outputs[0] != outputs[1]:
                differ += 1
                print(f"{key[0]}: {key[1]}: {name}: OUTPUTS DIFFER")
        compared += 1
    for (side, name), count in sorted(only.items()):
        print(f"buffer {name} only {side} (in {count} programs)")
    print(
        f"{compared} programs in both runs ({len(set(before) - set(after))} only before, "
        f"{len(set(after) - set(before))} only after); {buffers} buffers with equal inputs compared, "
        f"{differ} with different outputs"
    )
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
