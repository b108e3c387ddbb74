"""Compile the humanoid MJCF with MuJoCo and write the facts the Rust side needs as JSON.

The Rust crate does not parse MJCF. It reads `configs/characters/humanoid.json`, which this
script writes from the model MuJoCo compiles out of `configs/characters/humanoid.xml`:
bodies (tree, offsets, inertial frames, masses), joints (type, addresses, axes, ranges, damping),
geoms (shapes, for foot clearance), actuators, `qpos0`, the end-effector bodies and the feet.

The output is deterministic (sorted keys, fixed float formatting) so that CI can check that the
committed file matches the MJCF:

    python kernels_py/export_character.py           # (re)write the JSON, print nothing
    python kernels_py/export_character.py --check   # exit 1 and say why if the file differs

Needs the `mujoco` Python package (4.0.0 was used).
"""

import argparse
import sys
from pathlib import Path

import mujoco

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_XML = ROOT / "configs" / "characters" / "humanoid.xml"
DEFAULT_JSON = ROOT / "configs" / "characters" / "humanoid.json"

# The bodies whose frames the tracking reward and the observation follow (the MJCF has no notion
# of an end effector): DeepMimic's end effectors are the wrists and ankles; PHC-style
# observations add the head.
END_EFFECTORS = ["head", "right_hand", "left_hand", "right_foot", "left_foot"]
# The bodies that stand on the ground (lowest-foot checks of reference motions).
FEET = ["right_foot", "left_foot"]

JOINT_TYPES = {
    mujoco.mjtJoint.mjJNT_FREE: "free",
    mujoco.mjtJoint.mjJNT_BALL: "ball",
    mujoco.mjtJoint.mjJNT_SLIDE: "slide",
    mujoco.mjtJoint.mjJNT_HINGE: "hinge",
}

GEOM_TYPES = {
    mujoco.mjtGeom.mjGEOM_PLANE: "plane",
    mujoco.mjtGeom.mjGEOM_SPHERE: "sphere",
    mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule",
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
    mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
    mujoco.mjtGeom.mjGEOM_BOX: "box",
}


def num(x):
    """A float with 12 significant digits: exact for the values written in the MJCF, and stable
    against last-bit differences between MuJoCo builds for values it computes."""
    x = float(x)
    if x == 0.0:
        return "0"  # no "-0"
    return "%.12g" % x


def vec(values):
    return [float(v) for v in values]


def name(m, objtype, i):
    return mujoco.mj_id2name(m, objtype, i) or ""


def character_facts(m, xml_path):
    bodies = []
    for b in range(m.nbody):
        bodies.append(
            {
                "id": b,
                "name": name(m, mujoco.mjtObj.mjOBJ_BODY, b),
                # MuJoCo's world body is its own parent; -1 says "no parent" plainly.
                "parent": -1 if b == 0 else int(m.body_parentid[b]),
                "pos": vec(m.body_pos[b]),
                "quat": vec(m.body_quat[b]),
                "ipos": vec(m.body_ipos[b]),
                "iquat": vec(m.body_iquat[b]),
                "mass": float(m.body_mass[b]),
            }
        )
    joints = []
    for j in range(m.njnt):
        jtype = JOINT_TYPES[int(m.jnt_type[j])]
        joints.append(
            {
                "id": j,
                "name": name(m, mujoco.mjtObj.mjOBJ_JOINT, j),
                "type": jtype,
                "body": int(m.jnt_bodyid[j]),
                "qposadr": int(m.jnt_qposadr[j]),
                "dofadr": int(m.jnt_dofadr[j]),
                "axis": vec(m.jnt_axis[j]),
                "pos": vec(m.jnt_pos[j]),
                # The PD's Kd (docs/env.md): one value per joint in the MJCF, the same for all
                # of a joint's dofs. The ONNX export's deployment contract states it.
                "damping": float(m.dof_damping[m.jnt_dofadr[j]]),
                "limited": bool(m.jnt_limited[j]),
                "range": vec(m.jnt_range[j]),
            }
        )
    geoms = []
    for g in range(m.ngeom):
        gtype = int(m.geom_type[g])
        if gtype not in GEOM_TYPES:
            raise SystemExit(f"geom {g} has type {gtype}, which this exporter does not describe")
        geoms.append(
            {
                "id": g,
                "name": name(m, mujoco.mjtObj.mjOBJ_GEOM, g),
                "type": GEOM_TYPES[gtype],
                "body": int(m.geom_bodyid[g]),
                "size": vec(m.geom_size[g]),
                "pos": vec(m.geom_pos[g]),
                "quat": vec(m.geom_quat[g]),
            }
        )
    actuators = []
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT):
            raise SystemExit(f"actuator {a} does not act on a joint")
        actuators.append(
            {
                "id": a,
                "name": name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a),
                "joint": name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.actuator_trnid[a, 0])),
                "gear": vec(m.actuator_gear[a]),
                "ctrlrange": vec(m.actuator_ctrlrange[a]),
            }
        )
    body_names = [b["name"] for b in bodies]
    for body in END_EFFECTORS + FEET:
        if body not in body_names:
            raise SystemExit(f"{body!r} is not a body of {xml_path}")
    return {
        "source": str(xml_path.relative_to(ROOT)) if xml_path.is_relative_to(ROOT) else str(xml_path),
        "generator": "kernels_py/export_character.py",
        "mujoco_version": mujoco.__version__,
        "nq": int(m.nq),
        "nv": int(m.nv),
        "nu": int(m.nu),
        "nbody": int(m.nbody),
        "njnt": int(m.njnt),
        "total_mass": float(sum(m.body_mass)),
        "qpos0": vec(m.qpos0),
        "bodies": bodies,
        "joints": joints,
        "geoms": geoms,
        "actuators": actuators,
        "end_effectors": END_EFFECTORS,
        "feet": FEET,
    }


def emit(value, indent=0):
    """JSON with sorted keys, one object field per line, and lists of scalars on one line."""
    pad = "  " * indent
    if isinstance(value, dict):
        items = [f'{pad}  "{k}": {emit(value[k], indent + 1)}' for k in sorted(value)]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(value, list):
        if all(not isinstance(v, (dict, list)) for v in value):
            return "[" + ", ".join(emit(v, indent) for v in value) + "]"
        items = [pad + "  " + emit(v, indent + 1) for v in value]
        return "[\n" + ",\n".join(items) + "\n" + pad + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return num(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(f"cannot write {type(value)}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--xml", type=Path, default=DEFAULT_XML, help="MJCF to compile")
    parser.add_argument("--out", type=Path, default=DEFAULT_JSON, help="JSON to write or check")
    parser.add_argument("--check", action="store_true", help="compare with --out instead of writing it")
    args = parser.parse_args()

    xml_path = args.xml.resolve()
    model = mujoco.MjModel.from_xml_path(str(xml_path))
    text = emit(character_facts(model, xml_path)) + "\n"
    if args.check:
        try:
            current = args.out.read_text()
        except OSError as err:
            print(f"{args.out}: cannot read it ({err}); run {Path(__file__).name} without --check", file=sys.stderr)
            return 1
        if current != text:
            print(
                f"{args.out} differs from what {xml_path.name} compiles to; "
                f"run python {Path(__file__).relative_to(ROOT)} and commit the result",
                file=sys.stderr,
            )
            return 1
        return 0
    args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
