#!/usr/bin/env bash
# A character directory from a character file: the one build command of docs/characters.md.
#
#   kernels_py/build_character.sh CHARACTER.toml PHYSICS.toml OUT_DIR [NWORLDS]
#
# Needs an NVIDIA GPU (plans are captured on one), the Python packages of
# kernels_py/requirements.txt, and the instantmimic binary (on PATH, or $INSTANTMIMIC).
# NWORLDS defaults to "32 4096": the evaluation's and the training's world counts. It runs:
#   1. kernels_py/export_character.py: the simulation MJCF (when the character file adds to its
#      MJCF) and the description JSON, beside the character file;
#   2. kernels_py/capture.py: MuJoCo Warp's step and kinematics, captured on the GPU;
#   3. kernels_py/pack_plans.py: the plans packed (instantmimic plan pack);
#   4. kernels_py/compile.py: the PTX of every module the plans launch;
# and lays out OUT_DIR as `--character OUT_DIR` reads it:
#   OUT_DIR/character.json   the description
#   OUT_DIR/plans/           manifest.json and the packed plans
#   OUT_DIR/mjwarp/          the PTX
# PHYSICS.toml's `character` must name the simulation MJCF that step 1 writes.
set -euo pipefail
if [ $# -lt 3 ]; then
  sed -n '2,20p' "$0" >&2
  exit 2
fi
character=$1 physics=$2 out=$3 nworlds=${4:-"32 4096"}
here=$(cd "$(dirname "$0")" && pwd)
python=${PYTHON:-python3}
bin=${INSTANTMIMIC:-$(command -v instantmimic || true)}
[ -n "$bin" ] || { echo "error: no instantmimic binary: put it on PATH or set INSTANTMIMIC" >&2; exit 1; }
[ -f "$character" ] || { echo "error: $character does not exist (a character file, docs/characters.md)" >&2; exit 1; }
[ -f "$physics" ] || { echo "error: $physics does not exist (a physics config, configs/physics/g1.toml is an example)" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

echo "1/4 describing $character"
"$python" "$here/export_character.py" --character "$character"
description=${character%.toml}.json
echo "2/4 capturing plans for $nworlds worlds (a few minutes)"
# shellcheck disable=SC2086
"$python" "$here/capture.py" --physics "$physics" --nworld $nworlds --out "$work/capture"
echo "3/4 packing"
mkdir -p "$out"
"$python" "$here/pack_plans.py" --capture "$work/capture" --out "$out" --packer "$bin"
echo "4/4 compiling the modules' PTX"
"$python" "$here/compile.py" --only mjwarp --manifest "$out/plans/manifest.json" --out "$out"
cp "$description" "$out/character.json"
echo "done: $out (train with --character $out)"
