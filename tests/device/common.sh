# Shared by session.sh and campaign.sh (sourced, from the repository root): the staged binaries
# and the output directory.
#   BIN: the staged directory (tests/device/stage.sh); its bin.txz is unpacked once to /tmp.
#   OUT: where logs go (default /tmp/instantmimic-out).
BIN=${BIN:-.device-bin}
if [ -f "$BIN/bin.txz" ]; then
  mkdir -p /tmp/instantmimic-bin && tar xJf "$BIN/bin.txz" -C /tmp/instantmimic-bin && BIN=/tmp/instantmimic-bin
fi
BIN=$(cd "$BIN" && pwd)
OUT=${OUT:-/tmp/instantmimic-out}
mkdir -p "$OUT"
export INSTANTMIMIC_MOTIONS=${INSTANTMIMIC_MOTIONS:-$BIN/motions}

# The CUDA toolkit's library directory (cuBLAS), appended to LD_LIBRARY_PATH.
toolkit_libs() {
  local dir; dir=$(ls -d /usr/local/cuda*/lib64 2>/dev/null | sort -V | tail -1)
  echo "${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$dir"
}
