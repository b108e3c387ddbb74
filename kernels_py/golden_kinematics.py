"""Golden kinematics of each character from MuJoCo, for the Rust reference-motion tests.

For every character description `configs/characters/<name>.json` (its simulation MJCF is the
description's `source`), writes `tests/fixtures/kinematics_golden_<name>.json` with three seeded
sets of cases:

- `poses` (100): random qpos (root position in a box, uniformly random unit root and ball
  quaternions, hinge angles inside their ranges) with MuJoCo's body positions `xpos`, body
  orientations `xquat` and whole-body center of mass `subtree_com[0]` after `mj_kinematics`
  and `mj_comPos`.
- `velocities` (50): a random qvel for one of those poses, with each body's world-frame angular
  and linear velocity at its frame origin (`mj_objectVelocity`, `mjOBJ_XBODY`, world frame)
  and the center-of-mass velocity (`subtree_linvel[0]` from `mj_subtreeVel`).
- `differences` (100): a second qpos reached from one of the poses by `mj_integratePos`
  (with some quaternions negated, the same rotation) and `mj_differentiatePos` between them.

Every input is rounded to the printed precision before MuJoCo sees it, so the fixture holds the
exact inputs of the stored outputs. Bodies are MuJoCo bodies 1..nbody-1 (the world is left out),
flattened (x, y, z per body; w, x, y, z per quaternion).

    python kernels_py/golden_kinematics.py           # (re)write the fixtures, print nothing
    python kernels_py/golden_kinematics.py --check   # exit 1 if a committed fixture differs

Needs the `mujoco` Python package (4.0.0 was used) and numpy.
"""

import argparse
import json
import sys
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CHARACTERS = ROOT / "configs" / "characters"
FIXTURES = ROOT / "tests" / "fixtures"
SEED = 20260522
NUM_POSES = 100
NUM_VELOCITIES = 50
NUM_DIFFERENCES = 100
DIGITS = 9
# mj_differentiatePos outputs reach ~1000 (3 rad over 4 ms): more digits keep their rounding
# far below the 1e-6 tolerance. They are outputs only, never fed back to MuJoCo.
DIFFERENCE_DIGITS = 13


def rounded(values):
    """Round to DIGITS significant digits, the precision the fixture is written with."""
    return np.array([float("%.*g" % (DIGITS, v)) for v in np.ravel(values)])


def fmt(x, digits=DIGITS):
    x = float(x)
    return "0" if x == 0.0 else "%.*g" % (digits, x)


def random_qpos(m, rng):
    qpos = np.zeros(m.nq)
    for j in range(m.njnt):
        adr = m.jnt_qposadr[j]
        jtype = m.jnt_type[j]
        if jtype == mujoco.mjtJoint.mjJNT_FREE:
            qpos[adr : adr + 3] = rng.uniform([-3.0, -3.0, 0.3], [3.0, 3.0, 1.5])
            q = rng.normal(size=4)
            qpos[adr + 3 : adr + 7] = q / np.linalg.norm(q)
        elif jtype == mujoco.mjtJoint.mjJNT_BALL:
            q = rng.normal(size=4)
            qpos[adr : adr + 4] = q / np.linalg.norm(q)
        elif jtype == mujoco.mjtJoint.mjJNT_HINGE:
            lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-np.pi, np.pi)
            qpos[adr] = rng.uniform(lo, hi)
        else:
            raise SystemExit(f"joint {j}: slide joints are not supported by the reference kinematics")
    return rounded(qpos)


def quaternion_addresses(m):
    adrs = []
    for j in range(m.njnt):
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            adrs.append(m.jnt_qposadr[j] + 3)
        elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            adrs.append(m.jnt_qposadr[j])
    return adrs


def make_cases(m):
    rng = np.random.default_rng(SEED)
    d = mujoco.MjData(m)
    bodies = slice(1, m.nbody)

    poses = []
    for _ in range(NUM_POSES):
        d.qpos[:] = random_qpos(m, rng)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        poses.append(
            {
                "qpos": d.qpos.copy(),
                "xpos": d.xpos[bodies].ravel().copy(),
                "xquat": d.xquat[bodies].ravel().copy(),
                "com": d.subtree_com[0].copy(),
            }
        )

    velocities = []
    for _ in range(NUM_VELOCITIES):
        pose = int(rng.integers(NUM_POSES))
        d.qpos[:] = poses[pose]["qpos"]
        d.qvel[:] = rounded(rng.normal(scale=2.0, size=m.nv))
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_subtreeVel(m, d)
        angvel, linvel = [], []
        res = np.zeros(6)
        for b in range(1, m.nbody):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, b, res, 0)
            angvel.extend(res[:3])
            linvel.extend(res[3:])
        velocities.append(
            {
                "pose": pose,
                "qvel": d.qvel.copy(),
                "angvel": np.array(angvel),
                "linvel": np.array(linvel),
                "com_vel": d.subtree_linvel[0].copy(),
            }
        )

    quats = quaternion_addresses(m)
    differences = []
    for i in range(NUM_DIFFERENCES):
        pose = int(rng.integers(NUM_POSES))
        qpos_a = poses[pose]["qpos"]
        dt = float(rounded([rng.uniform(0.004, 0.05)])[0])
        # Mostly control-step-sized motions; every fourth case turns far (up to ~3 rad) to
        # exercise the shortest-path branch of the quaternion difference.
        scale = 60.0 if i % 4 == 3 else 4.0
        v = rng.normal(scale=scale, size=m.nv)
        qpos_b = qpos_a.copy()
        mujoco.mj_integratePos(m, qpos_b, v, dt)
        for adr in quats:
            if rng.uniform() < 0.3:
                qpos_b[adr : adr + 4] *= -1.0
        qpos_b = rounded(qpos_b)
        qvel = np.zeros(m.nv)
        mujoco.mj_differentiatePos(m, qvel, dt, qpos_a, qpos_b)
        differences.append({"pose": pose, "qpos_b": qpos_b, "dt": dt, "qvel": qvel})

    return poses, velocities, differences


def emit_case(case, digits=None):
    """One case on one line; `digits` maps a key to its number of significant digits."""
    digits = digits or {}
    fields = []
    for key in sorted(case):
        value = case[key]
        n = digits.get(key, DIGITS)
        if isinstance(value, int):
            fields.append(f'"{key}": {value}')
        elif isinstance(value, float):
            fields.append(f'"{key}": {fmt(value, n)}')
        else:
            fields.append(f'"{key}": [' + ",".join(fmt(v, n) for v in value) + "]")
    return "    {" + ", ".join(fields) + "}"


def emit(m, xml, poses, velocities, differences):
    lines = [
        "{",
        '  "generator": "kernels_py/golden_kinematics.py",',
        f'  "mujoco_version": "{mujoco.__version__}",',
        f'  "character": "{xml}",',
        f'  "seed": {SEED},',
        f'  "nq": {m.nq}, "nv": {m.nv}, "nbody": {m.nbody},',
    ]
    for name, cases, digits, last in (
        ("poses", poses, None, False),
        ("velocities", velocities, None, False),
        ("differences", differences, {"qvel": DIFFERENCE_DIGITS}, True),
    ):
        lines.append(f'  "{name}": [')
        lines.append(",\n".join(emit_case(c, digits) for c in cases))
        lines.append("  ]" + ("" if last else ","))
    lines.append("}")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed fixtures")
    args = parser.parse_args()

    failed = False
    for description in sorted(CHARACTERS.glob("*.json")):
        xml = json.loads(description.read_text())["source"]
        out = FIXTURES / f"kinematics_golden_{description.stem}.json"
        m = mujoco.MjModel.from_xml_path(str(ROOT / xml))
        text = emit(m, xml, *make_cases(m))
        if not args.check:
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(text)
            continue
        try:
            current = out.read_text()
        except OSError as err:
            print(f"{out}: cannot read it ({err})", file=sys.stderr)
            failed = True
            continue
        if current != text:
            print(f"{out} differs from what {Path(__file__).name} computes now", file=sys.stderr)
            failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
