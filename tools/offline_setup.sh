#!/usr/bin/env bash
# A GPU machine with no package index (docs/portability.md, "A GPU machine with no package index"): install the
# wheels carried in WHEELS into SITE (default /tmp/site), list NVIDIA's OpenCL driver where the image lacks its ICD
# file, and print the exports that put them in use, for eval:
#
#   exports=$(tools/offline_setup.sh WHEELS [SITE]) && eval "$exports"
#
# WHEELS holds the .whl files of that section's list and, in WHEELS/lib, the libOpenCL.so.1 that pyvkfft links to.
# The checkout itself goes on PYTHONPATH (its kernels/ are found beside the package) and PYTHON names the image's
# python3, which tools/device_report.sh then uses. Every message goes to stderr; a failed install exits non-zero.
set -euo pipefail
[ $# -ge 1 ] || { sed -n '6p' "$0" | sed 's/^# *//' >&2; exit 2; }
WHEELS=$(cd "$1" && pwd)
SITE=${2:-/tmp/site}
REPO=$(cd "$(dirname "$0")/.." && pwd)
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" "$WHEELS"/*.whl >&2
VENDORS=/etc/OpenCL/vendors
if ! grep -qs nvidia "$VENDORS"/*.icd; then
    # NVIDIA's OpenCL driver: from the linker's cache, else from the usual driver folders
    driver=$(ldconfig -p 2>/dev/null | awk '/libnvidia-opencl\.so\.1 .*x86-64/ {print $NF; exit}' || true)
    [ -n "$driver" ] || driver=$(find /usr/local/nvidia /usr/lib/x86_64-linux-gnu /usr/lib64 /usr/lib \
        -name 'libnvidia-opencl.so.1' 2>/dev/null | grep -v -e i386 -e /lib32/ | head -n 1 || true)
    if [ -n "$driver" ]; then
        if ! { mkdir -p "$VENDORS" && echo "$driver" >"$VENDORS/nvidia.icd"; }; then
            echo "offline_setup: cannot write $VENDORS/nvidia.icd (not root?)" >&2
            exit 1
        fi
        echo "offline_setup: $VENDORS/nvidia.icd names $driver" >&2
    else
        echo "offline_setup: no libnvidia-opencl.so.1 found: NVIDIA's OpenCL driver is not listed" >&2
    fi
fi
printf 'export PYTHONPATH=%q LD_LIBRARY_PATH=%q PYTHON=python3\n' "$SITE:$REPO${PYTHONPATH:+:$PYTHONPATH}" \
    "$WHEELS/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
