#!/usr/bin/env bash
# Downloads into device_wheels/ (ignored by git) the wheels a lent GPU machine lacks to run
# benchmarks/device_throughput.py: its image has Python 3.12 with torch and numpy, and no network. Ray
# 2.60.0 comes stripped of ray/jars/ (Java workers) and ray/dashboard/client/ (the dashboard's web
# page), which nothing here uses, so that everything fits in 64 MiB (the most a device run carries).
#
#   bash scripts/gather_device_wheels.sh [DIR]        (default DIR: device_wheels)
#
# On the GPU machine, from the checkout (the device run carries DIR along):
#
#   python3 -m pip install --no-index --no-deps --target /tmp/site device_wheels/*.whl
#   PYTHONPATH=.:/tmp/site python3 benchmarks/device_throughput.py --suite
#
# (`bash scripts/device_check.sh` does both and keeps the output.) Prints each wheel's size and the total;
# exits 1 when the total is over 64 MiB.
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${1:-device_wheels}"
limit=$((64 * 1024 * 1024))
python_bin="${PYTHON:-.venv/bin/python}"
command -v "$python_bin" >/dev/null 2>&1 || python_bin=python3

mkdir -p "$dir"
# Exact versions: what this checkout is tested with (pyproject.toml, .venv).
wheels=(
  "ray==2.60.0"
  "gymnasium==1.2.2"
  "farama-notifications"
  "dm-tree"
  "lz4"
  "ormsgpack"
  "tensorboardX"
  "jsonschema"
  "jsonschema-specifications"
  "referencing"
  "rpds-py"
  "pydantic"
  "pydantic-core"
  "annotated-types"
  "typing-inspection"
)
"$python_bin" -m pip download --disable-pip-version-check --quiet --no-deps --dest "$dir" \
  --python-version 3.12 --implementation cp --abi cp312 --only-binary=:all: \
  --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux_2_28_x86_64 \
  "${wheels[@]}"

# Strip ray's jars and dashboard page, and their lines in the wheel's RECORD (pip checks every file
# it installs against RECORD; a file that is not there is simply not installed).
# Idempotent: a wheel stripped before is copied as it is.
ray_wheel="$(ls "$dir"/ray-2.60.0-*.whl)"
"$python_bin" - "$ray_wheel" <<'EOF'
import os
import sys
import zipfile

path = sys.argv[1]
dropped = ("ray/jars/", "ray/dashboard/client/")
stripped = path + ".stripped"
with zipfile.ZipFile(path) as src, zipfile.ZipFile(stripped, "w", zipfile.ZIP_DEFLATED) as dst:
    for item in src.infolist():
        if item.filename.startswith(dropped):
            continue
        data = src.read(item.filename)
        if item.filename.endswith(".dist-info/RECORD"):
            lines = data.decode().splitlines(keepends=True)
            data = "".join(line for line in lines if not line.startswith(dropped)).encode()
        dst.writestr(item, data)
os.replace(stripped, path)
EOF

total=0
for wheel in "$dir"/*.whl; do
  size=$(stat -c %s "$wheel")
  total=$((total + size))
  printf '%8.1f MiB  %s\n' "$(echo "$size / 1048576" | bc -l)" "$(basename "$wheel")"
done
printf '%8.1f MiB  in all (limit 64 MiB)\n' "$(echo "$total / 1048576" | bc -l)"
if [ "$total" -gt "$limit" ]; then
  echo "error: the wheels in $dir come to more than 64 MiB" >&2
  exit 1
fi
