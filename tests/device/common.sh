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
# The Python with TensorBoard's reader (gpu_tensorboard reads the event files back with it): the
# GPU machine's image has one in /opt/torch/.venv.
if [ -z "${INSTANTMIMIC_BUILD_PYTHON:-}" ] && [ -x /opt/torch/.venv/bin/python3 ]; then
  export INSTANTMIMIC_BUILD_PYTHON=/opt/torch/.venv/bin/python3
fi

# The CUDA toolkit's library directory (cuBLAS), appended to LD_LIBRARY_PATH.
toolkit_libs() {
  local dir; dir=$(ls -d /usr/local/cuda*/lib64 2>/dev/null | sort -V | tail -1)
  echo "${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$dir"
}

# NCCL's library directory (training on several GPUs, gpu_multi_gpu), appended to
# LD_LIBRARY_PATH: $NCCL_LIB_DIR, else PyTorch's bundled copy in /opt/torch/.venv (the GPU
# machine has NCCL only there), else pip's nvidia-nccl wheel of the system Python. NCCL opens
# libnccl.so.2 from it. NCCL_NVLS_ENABLE=0 stays as the machine sets it (instantmimic sets it
# itself when it is unset: no NVLink multicast).
nccl_libs() {
  local dir=${NCCL_LIB_DIR:-}
  [ -n "$dir" ] || dir=$(ls -d /opt/torch/.venv/lib/python3*/site-packages/nvidia/nccl/lib 2>/dev/null | sort -V | tail -1)
  [ -n "$dir" ] || dir=$(python3 -c 'import nvidia.nccl, pathlib; print(pathlib.Path(list(nvidia.nccl.__path__)[0]) / "lib")' 2>/dev/null)
  echo "${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$dir"
}

# Visible GPUs.
gpu_count() {
  nvidia-smi -L 2>/dev/null | grep -c '^GPU'
}

# The older build of a before/after comparison: unpacks $BEFORE/instantmimic.xz once and
# defines `binary before|after` (the older build, or the staged one). Exits when BEFORE is not
# such a directory.
unpack_before() {
  [ -f "${BEFORE:-}/instantmimic.xz" ] || { echo "BEFORE=DIR must hold instantmimic.xz (the older build)" >&2; exit 2; }
  mkdir -p /tmp/instantmimic-before && xz -dc "$BEFORE/instantmimic.xz" > /tmp/instantmimic-before/instantmimic \
    && chmod +x /tmp/instantmimic-before/instantmimic
}
binary() { if [ "$1" = before ]; then echo /tmp/instantmimic-before/instantmimic; else echo "$BIN/instantmimic"; fi; }
