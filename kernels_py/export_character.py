"""Compile a character's MJCF with MuJoCo and write the facts the Rust side needs as JSON.

A character is two files of ours in configs/characters/: `<name>.toml`, the character file
(what the MJCF does not say: anchor, tracked bodies, end effectors, feet, PD gains, armature,
effort limits, action scales, the default pose, contact settings), and the MJCF it names. When
the character file adds anything to the model (motors, damping, armature, contact settings, a
floor), this script writes the simulation model `simulation_mjcf`; the physics plans are
captured from that file. It then writes `<name>.json`, the description the binary reads: bodies
(tree, offsets, inertial frames, masses), joints (type, addresses, axes, ranges, damping), geoms,
actuators, `qpos0`, the default pose, gravity, each actuated joint's control and the body lists.

The output is deterministic (sorted keys, fixed float formatting) so that CI can check that the
committed files match their sources (docs/characters.md):

    python kernels_py/export_character.py                   # every configs/characters/*.toml
    python kernels_py/export_character.py --character g1    # one character (name or .toml path)
    python kernels_py/export_character.py --check           # exit 1 and say why if a file differs

Needs the `mujoco` Python package (4.0.0 was used).
"""

import argparse
import fnmatch
import sys
import tomllib
from pathlib import Path

import mujoco

ROOT = Path(__file__).resolve().parent.parent
CHARACTERS = ROOT / "configs" / "characters"


class CharacterFileError(SystemExit):
    """A character file that cannot be compiled: the message names the file and the fix."""


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


def character_facts(m, xml_path, character):
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
    where = character["toml"]
    for what in ("end_effectors", "feet"):
        for body in character[what]:
            if body not in body_names[1:]:
                raise CharacterFileError(f"{where}: {what} names {body!r}, which is not a body of {xml_path.name}")
    if character["anchor"] not in body_names[1:]:
        raise CharacterFileError(f"{where}: anchor {character['anchor']!r} is not a body of {xml_path.name}")
    tracked = character["tracked_bodies"]
    if tracked == "all":
        tracked = body_names[1:]
    for body in tracked:
        if body not in body_names[1:]:
            raise CharacterFileError(f"{where}: tracked_bodies names {body!r}, which is not a body of {xml_path.name}")
    return {
        "name": character["name"],
        "source": relative(xml_path),
        "character_file": relative(character["path"]),
        "generator": "kernels_py/export_character.py",
        "mujoco_version": mujoco.__version__,
        "nq": int(m.nq),
        "nv": int(m.nv),
        "nu": int(m.nu),
        "nbody": int(m.nbody),
        "njnt": int(m.njnt),
        "total_mass": float(sum(m.body_mass)),
        "gravity": vec(m.opt.gravity),
        "qpos0": vec(m.qpos0),
        "default_qpos": default_qpos(m, character),
        "bodies": bodies,
        "joints": joints,
        "geoms": geoms,
        "actuators": actuators,
        "control": joint_control(m, character),
        "anchor": character["anchor"],
        "tracked_bodies": list(tracked),
        "end_effectors": list(character["end_effectors"]),
        "feet": list(character["feet"]),
    }


def relative(path):
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def matches(name, patterns):
    return any(fnmatch.fnmatchcase(name, p) for p in patterns)


def joint_groups(m, character):
    """Each ball or hinge joint's group of the character file: exactly one must match."""
    groups = {}
    for j in range(m.njnt):
        if int(m.jnt_type[j]) == mujoco.mjtJoint.mjJNT_FREE:
            continue
        jname = name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        found = [g for g in character["joints"] if matches(jname, g["match"])]
        if len(found) != 1:
            raise CharacterFileError(
                f"{character['toml']}: joint {jname!r} matches {len(found)} [[joints]] groups; "
                "every ball or hinge joint needs exactly one"
            )
        groups[j] = found[0]
    return groups


def joint_actuators(m, j):
    return [a for a in range(m.nu) if int(m.actuator_trnid[a, 0]) == j]


def joint_control(m, character):
    """One entry per ball or hinge joint, in joint order: what the kernels' PD needs."""
    action = character["action"]
    control = []
    for j, group in joint_groups(m, character).items():
        jname = name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        dof = int(m.jnt_dofadr[j])
        hinge = int(m.jnt_type[j]) == mujoco.mjtJoint.mjJNT_HINGE
        motors = joint_actuators(m, j)
        if not motors:
            raise CharacterFileError(f"{character['toml']}: joint {jname!r} has no motor; give its group an effort_limit")
        # The torque limit: the first motor's ctrlrange times its gear (gear 1 here).
        effort = abs(float(m.actuator_ctrlrange[motors[0], 1]) * float(m.actuator_gear[motors[0], 0] or 1.0))
        lo, hi = (float(v) for v in m.jnt_range[j])
        limited = bool(m.jnt_limited[j]) and hi > lo
        if not hinge:
            scale, center = 1.0, 0.0
        else:
            if action["scale"] == "half_range":
                scale = 0.5 * (hi - lo) if limited else 1.0
            else:
                scale = float(group["action_scale"])
            if action["center"] == "mid_range":
                center = 0.5 * (hi + lo) if limited else 0.0
            else:
                center = float(default_qpos(m, character)[int(m.jnt_qposadr[j])])
        control.append(
            {
                "joint": jname,
                "kp": float(group["kp"]),
                "kd": float(m.dof_damping[dof]),
                "armature": float(m.dof_armature[dof]),
                "effort_limit": effort,
                "action_scale": scale,
                "action_center": center,
            }
        )
    return control


def default_qpos(m, character):
    """qpos0 with the character file's root height and joint angles."""
    qpos = [float(v) for v in m.qpos0]
    pose = character.get("default_pose", {})
    for j in range(m.njnt):
        adr = int(m.jnt_qposadr[j])
        jtype = int(m.jnt_type[j])
        if jtype == mujoco.mjtJoint.mjJNT_FREE and "root_height" in pose:
            qpos[adr + 2] = float(pose["root_height"])
        elif jtype == mujoco.mjtJoint.mjJNT_HINGE:
            jname = name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            for pattern, angle in pose.get("joints", {}).items():
                if fnmatch.fnmatchcase(jname, pattern):
                    qpos[adr] = float(angle)
    return qpos


def read_character(arg):
    """The character file named by `arg` (a name in configs/characters or a .toml path)."""
    path = Path(arg)
    if path.suffix != ".toml":
        path = CHARACTERS / f"{arg}.toml"
    try:
        character = tomllib.loads(path.read_text())
    except OSError as err:
        raise CharacterFileError(f"{path}: cannot read it ({err})")
    except tomllib.TOMLDecodeError as err:
        raise CharacterFileError(f"{path}: {err}")
    known = {"mjcf", "simulation_mjcf", "anchor", "tracked_bodies", "end_effectors", "feet", "action", "joints", "default_pose", "contact"}
    unknown = sorted(set(character) - known)
    if unknown:
        raise CharacterFileError(f"{path}: unknown keys {unknown}; the keys are {sorted(known)}")
    for key in ("mjcf", "anchor", "end_effectors", "feet", "action", "joints"):
        if key not in character:
            raise CharacterFileError(f"{path}: the key {key!r} is missing (docs/characters.md)")
    character.setdefault("tracked_bodies", "all")
    if character["action"].get("center") not in ("mid_range", "default_pose") or character["action"].get("scale") not in ("half_range", "per_joint"):
        raise CharacterFileError(f"{path}: [action] needs center = \"mid_range\" or \"default_pose\" and scale = \"half_range\" or \"per_joint\"")
    character["path"] = path.resolve()
    character["toml"] = relative(path)
    character["name"] = path.stem
    return character


def simulation_spec(character):
    """The MJCF with what the character file adds: a motor, damping and armature per joint whose
    group gives them, contact settings per geom pattern, a floor. None when nothing is added."""
    source = character["path"].parent / character["mjcf"]
    spec = mujoco.MjSpec.from_file(str(source))
    changed = False
    model = spec.compile()
    groups = joint_groups(model, character)
    for j, group in groups.items():
        joint = spec.joint(name(model, mujoco.mjtObj.mjOBJ_JOINT, j))
        if "kd" in group:
            joint.damping = [float(group["kd"]), 0.0, 0.0]
            changed = True
        if "armature" in group:
            joint.armature = float(group["armature"])
            changed = True
        if "effort_limit" in group:
            if joint_actuators(model, j):
                raise CharacterFileError(f"{character['toml']}: joint {joint.name!r} already has a motor in the MJCF; drop effort_limit from its group")
            if int(model.jnt_type[j]) != mujoco.mjtJoint.mjJNT_HINGE:
                raise CharacterFileError(f"{character['toml']}: joint {joint.name!r}: motors are added for hinges only")
            limit = float(group["effort_limit"])
            spec.add_actuator(
                name=joint.name,
                target=joint.name,
                trntype=mujoco.mjtTrn.mjTRN_JOINT,
                gear=[1, 0, 0, 0, 0, 0],
                ctrllimited=True,
                ctrlrange=[-limit, limit],
            )
            changed = True
    contact = character.get("contact", {})
    for entry in contact.get("geoms", []):
        hit = False
        for geom in spec.geoms:
            if geom.name and matches(geom.name, entry["match"]):
                hit = True
                for key in ("contype", "conaffinity", "condim", "priority"):
                    if key in entry:
                        setattr(geom, key, int(entry[key]))
                if "friction" in entry:
                    geom.friction = [float(entry["friction"]), geom.friction[1], geom.friction[2]]
        if not hit:
            raise CharacterFileError(f"{character['toml']}: [[contact.geoms]] {entry['match']} matches no geom")
        changed = True
    if contact.get("floor", False):
        has_plane = any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.worldbody.geoms)
        if not has_plane:
            spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1], contype=1, conaffinity=1)
            changed = True
    return spec if changed else None


def outputs(character):
    """(path, text) of each file the character compiles to, and the path of the simulation model."""
    files = []
    source = character["path"].parent / character["mjcf"]
    spec = simulation_spec(character)
    if spec is not None:
        if "simulation_mjcf" not in character:
            raise CharacterFileError(f"{character['toml']}: it adds to the MJCF, so it needs simulation_mjcf = \"<name>.xml\" (where to write the model)")
        xml_path = character["path"].parent / character["simulation_mjcf"]
        header = (
            f"<!-- Generated by kernels_py/export_character.py from {relative(source)} and "
            f"{character['toml']}; do not edit. See the source's header for its licence. -->\n"
        )
        files.append((xml_path, header + spec.to_xml()))
        model = spec.compile()
    else:
        xml_path = source
        model = mujoco.MjModel.from_xml_path(str(source))
    json_path = character["path"].with_suffix(".json")
    files.append((json_path, emit(character_facts(model, xml_path.resolve(), character)) + "\n"))
    return files


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
    parser.add_argument(
        "--character",
        action="append",
        help="a character name in configs/characters or a .toml path (default: every configs/characters/*.toml)",
    )
    parser.add_argument("--check", action="store_true", help="compare with the committed files instead of writing them")
    args = parser.parse_args()

    names = args.character or sorted(str(p) for p in CHARACTERS.glob("*.toml"))
    failed = False
    for arg in names:
        for path, text in outputs(read_character(arg)):
            if not args.check:
                path.write_text(text)
                continue
            try:
                current = path.read_text()
            except OSError as err:
                print(f"{path}: cannot read it ({err}); run {Path(__file__).name} without --check", file=sys.stderr)
                failed = True
                continue
            if current != text:
                print(
                    f"{relative(path)} differs from what its character file compiles to; "
                    f"run python {Path(__file__).relative_to(ROOT)} and commit the result",
                    file=sys.stderr,
                )
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
