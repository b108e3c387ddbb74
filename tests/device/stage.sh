#!/usr/bin/env bash
# Build the release binary and the GPU test binaries here, and stage them for the GPU machine.
#   tests/device/stage.sh [--train-only] [--only "gpu_a gpu_b ..."] [DIR]
#   (DIR default .device-bin; ignored by git via .git/info/exclude)
# --train-only stages the release binary alone (a training campaign, tests/device/campaign.sh).
# --only stages the release binary and the named test and benchmark binaries alone: the whole
# set packs to about 35 MB, which with the 21 MB tree leaves little of a call's 64 MiB for run
# directories carried from an earlier call.
# DIR then holds bin.txz: `instantmimic`, one stripped binary per tests/gpu_*.rs (named after
# the file), one per benches/*.rs (bench_<name>), and motions/ (session.sh's INSTANTMIMIC_MOTIONS): the
# shipped clips are built into the binaries, so it holds only DeepMimic's long clips
# (../shared/data/motions/long, kept out of the repository) when they are there.
# Carry DIR in the device call and run tests/device/session.sh there.
set -euo pipefail
cd "$(dirname "$0")/../.."
TRAIN_ONLY=0
ONLY=
while [ $# -gt 0 ]; do
  case "$1" in
    --train-only) TRAIN_ONLY=1; shift ;;
    --only) [ $# -ge 2 ] || { echo "stage.sh: --only needs a list of binaries" >&2; exit 2; }
            ONLY=$2; shift 2 ;;
    -*) echo "stage.sh: unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
DIR=${1:-.device-bin}
LONG_MOTIONS=$(cd .. && pwd)/shared/data/motions/long
mkdir -p .git/info
grep -qx "/$DIR/" .git/info/exclude 2>/dev/null || echo "/$DIR/" >> .git/info/exclude
rm -rf "$DIR"; mkdir -p "$DIR"
cargo build --release --quiet
cp target/release/instantmimic "$DIR/"
if [ "$TRAIN_ONLY" = 0 ]; then
cargo test --release --features gpu --no-run --message-format=json 2>/dev/null \
  | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"].startswith("gpu_"):
        print(m["target"]["name"], m["executable"])
' | while read -r name exe; do cp "$exe" "$DIR/$name"; done
# The cargo benchmarks (benches/*.rs), as bench_<name>.
cargo bench --features gpu --no-run --message-format=json 2>/dev/null \
  | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and "bench" in m["target"]["kind"]:
        print(m["target"]["name"], m["executable"])
' | while read -r name exe; do cp "$exe" "$DIR/bench_$name"; done
fi
if [ -n "$ONLY" ]; then
  for name in $ONLY; do
    [ -f "$DIR/$name" ] || { echo "stage.sh: --only names $name, which is no test or benchmark binary" >&2; exit 2; }
  done
  for f in "$DIR"/*; do
    name=$(basename "$f")
    [ "$name" = instantmimic ] && continue
    case " $ONLY " in *" $name "*) ;; *) rm -f "$f" ;; esac
  done
fi
strip "$DIR"/*
mkdir -p "$DIR/motions"
if [ -d "$LONG_MOTIONS" ]; then cp -r "$LONG_MOTIONS" "$DIR/motions/long"; fi
# Unpacked the binaries pass the 64 MiB a device call carries: ship them xz-packed
# (session.sh unpacks DIR/bin.txz).
tar cJf /tmp/instantmimic-bin.txz -C "$DIR" . && rm -rf "${DIR:?}"/* && mv /tmp/instantmimic-bin.txz "$DIR/bin.txz"
du -sh "$DIR"; ls "$DIR"
