#!/usr/bin/env bash
# The test command (README; CI runs exactly this). No GPU needed.
#
# With no arguments (CI): the gates first, `cargo fmt --check`, `cargo clippy --all-targets
# --all-features -- -D warnings` and a build of the GPU tests and benchmarks (`--features gpu`:
# they run on the GPU machine, tests/device/session.sh, but must compile everywhere), then
# `cargo test`. With arguments, only `cargo test ARGS` (e.g. `tests/run.sh --test train_cli`).
#
# Sets up the build-step Python once (kernels_py/requirements.txt, in .venv) so that the tests
# also check that ptx/ regenerates from kernels_py/ byte for byte and that every shipped PTX
# assembles with ptxas for every supported GPU, then runs `cargo test`. The tests read the
# DeepMimic clips shipped in assets/motions/ (built into the binary) and need no other data;
# DeepMimic's long clips, kept out of the repository, are checked too when
# $INSTANTMIMIC_MOTIONS names a directory with long/ (default ../shared/data/motions if present).
# The exports' and the replay page's checks need outside tools, installed here when missing:
# Debian's chromium (the page in a headless browser), and npm's gltf-validator (tests/tools);
# onnxruntime (the ONNX export's check) comes with kernels_py/requirements.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${INSTANTMIMIC_VENV:-.venv}
# Relative to the repository root unless absolute.
case $venv in /*) ;; *) venv=$PWD/$venv ;; esac
if [ ! -x "$venv/bin/python" ] || ! cmp -s kernels_py/requirements.txt "$venv/requirements.txt"; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r kernels_py/requirements.txt
  cp kernels_py/requirements.txt "$venv/requirements.txt"
fi
INSTANTMIMIC_BUILD_PYTHON="$venv/bin/python"
PTXAS=$("$INSTANTMIMIC_BUILD_PYTHON" -c 'import nvidia.cu13, pathlib; print(pathlib.Path(nvidia.cu13.__path__[0]) / "bin" / "ptxas")')
export INSTANTMIMIC_BUILD_PYTHON PTXAS
# The default only where it exists: without a long/ there the long clips are not checked (the
# test prints a note and passes).
if [ -z "${INSTANTMIMIC_MOTIONS:-}" ] && [ -d ../shared/data/motions ]; then
  INSTANTMIMIC_MOTIONS=$(cd ../shared/data/motions && pwd)
  export INSTANTMIMIC_MOTIONS
fi
# The replay page's test opens it in headless Chromium (tests/viewer_page.rs): Debian's package,
# installed here when missing (INSTANTMIMIC_CHROMIUM names another binary).
if [ -z "${INSTANTMIMIC_CHROMIUM:-}" ] && ! command -v chromium >/dev/null 2>&1; then
  echo "installing chromium (Debian) for the replay page's browser test"
  sudo=; [ "$(id -u)" -eq 0 ] || sudo=sudo
  $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq chromium >/dev/null \
    || { echo "error: cannot install chromium; install it, or set INSTANTMIMIC_CHROMIUM to a Chromium binary" >&2; exit 1; }
fi
INSTANTMIMIC_CHROMIUM=${INSTANTMIMIC_CHROMIUM:-$(command -v chromium)}
export INSTANTMIMIC_CHROMIUM
# The .glb export is checked by the Khronos glTF validator (npm, pinned in tests/tools).
if ! command -v npm >/dev/null 2>&1; then
  echo "installing nodejs and npm (Debian) for the glTF validator"
  sudo=; [ "$(id -u)" -eq 0 ] || sudo=sudo
  $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq nodejs npm >/dev/null \
    || { echo "error: cannot install nodejs and npm (the glTF validator runs on node)" >&2; exit 1; }
fi
if [ ! -d tests/tools/node_modules/gltf-validator ] \
  || ! cmp -s tests/tools/package-lock.json tests/tools/node_modules/.installed-lock.json; then
  npm ci --prefix tests/tools --no-audit --no-fund --silent
  cp tests/tools/package-lock.json tests/tools/node_modules/.installed-lock.json
fi
INSTANTMIMIC_GLTF_VALIDATOR=$PWD/tests/tools/validate_gltf.mjs
export INSTANTMIMIC_GLTF_VALIDATOR
if [ "$#" -eq 0 ]; then
  # Every tool is installed above: a test that would skip for want of one fails instead
  # (tests/skip_support).
  export INSTANTMIMIC_NO_SKIP=1
  cargo fmt --check
  cargo clippy --all-targets --all-features -- -D warnings
  cargo test --features gpu --no-run --quiet
  # The README's install step, as a new user takes it (`cargo install --path .`), into a
  # directory of its own instead of ~/.cargo; tests/readme_commands.rs then runs the README's
  # commands with that directory on the PATH.
  cargo install --path . --locked --quiet --force --root target/new-user --target-dir target
  INSTANTMIMIC_INSTALLED_BIN=$PWD/target/new-user/bin
  export INSTANTMIMIC_INSTALLED_BIN
fi
exec cargo test "$@"
