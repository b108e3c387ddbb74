#!/usr/bin/env bash
# Stage only the release binary and the motions for a training campaign on the GPU machine
# (tests/device/stage.sh also builds every GPU test and benchmark, which a campaign needs not).
#   tests/device/stage_train.sh [DIR]      (default .device-bin)
set -euo pipefail
cd "$(dirname "$0")/../.."
DIR=${1:-.device-bin}
# The clips are built into the binary; only the long ones (kept out of the repository) travel.
LONG_MOTIONS=$(cd .. && pwd)/shared/data/motions/long
mkdir -p .git/info
grep -qx "/$DIR/" .git/info/exclude 2>/dev/null || echo "/$DIR/" >> .git/info/exclude
rm -rf "$DIR"; mkdir -p "$DIR/stage"
cargo build --release --quiet
cp target/release/instantmimic "$DIR/stage/"
strip "$DIR/stage/instantmimic"
mkdir -p "$DIR/stage/motions"
if [ -d "$LONG_MOTIONS" ]; then cp -r "$LONG_MOTIONS" "$DIR/stage/motions/long"; fi
tar cJf "$DIR/bin.txz" -C "$DIR/stage" . && rm -rf "$DIR/stage"
du -sh "$DIR"
