#!/usr/bin/env bash
# Downloads into device_wheels/ (ignored by git) the wheels a lent GPU machine lacks to run
# scripts/device_check.sh: its image has Python 3.12 with torch and numpy, and no network. Ray 2.60.0
# comes stripped of ray/jars/ (Java workers), ray/dashboard/client/ (the dashboard's web page),
# ray/serve/ and ray/llm/, which nothing here uses, so that everything fits in 64 MiB (the most a
# device run carries, with the checkout: `python3 scripts/device_tree.py size` says).
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
  # MLflow's SQLite store, for the short sweep (`python -m copilot_ray.sweep`) and its `carry`: the
  # skinny distribution is the whole `mlflow` package without the UI's web page (which nothing there
  # serves), and these are what it imports to write runs (scripts/device_image/sitecustomize.py shows
  # a rehearsal what else a run would import).
  "mlflow-skinny==3.17.2"
  "sqlalchemy==2.1.9"
  "alembic==1.20.1"
  "mako==1.4.3"
  "sqlparse==0.6.1"
  "cachetools==7.3.3"
  "importlib-metadata==9.1.0"
  "opentelemetry-api==1.45.2"
  "opentelemetry-sdk==1.45.2"
  "opentelemetry-proto==1.45.2"
  "opentelemetry-semantic-conventions==0.66b2"
  # imported by `import mlflow` itself: its gateway (fastapi, starlette), its evaluation (asks whether
  # databricks.agents exists, which needs the databricks package), its registry's tables (Fernet)
  "fastapi==0.165.0"
  "starlette==1.10.0"
  "databricks-sdk==0.162.0"
  "cryptography==50.0.2"
  "cffi==2.1.1"
)
# Downloaded into a folder of their own, then moved in: a wheel already in DIR (stripped, recompressed)
# stays as it is, one no longer asked for goes, so DIR holds exactly the requirements' wheels.
fresh="$(mktemp -d)"
trap 'rm -rf "$fresh"' EXIT
"$python_bin" -m pip download --disable-pip-version-check --quiet --no-deps --dest "$fresh" \
  --python-version 3.12 --implementation cp --abi cp312 --only-binary=:all: \
  --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux_2_28_x86_64 \
  "${wheels[@]}"
for wheel in "$dir"/*.whl; do
  [ -e "$wheel" ] && [ ! -e "$fresh/$(basename "$wheel")" ] && rm -v "$wheel"
done
for wheel in "$fresh"/*.whl; do
  [ -e "$dir/$(basename "$wheel")" ] || mv "$wheel" "$dir/"
done

# Strip ray's jars, dashboard page, Serve and LLM libraries (none of which a trial imports), and their
# lines in the wheel's RECORD (pip checks every file it installs against RECORD; a file that is not
# there is simply not installed). Idempotent: a wheel stripped before is left as it is.
ray_wheel="$(ls "$dir"/ray-2.60.0-*.whl)"
"$python_bin" - "$ray_wheel" <<'EOF'
import os
import sys
import zipfile

path = sys.argv[1]
dropped = ("ray/jars/", "ray/dashboard/client/", "ray/serve/", "ray/llm/")
stripped = path + ".stripped"
with zipfile.ZipFile(path) as src:
    if not any(name.startswith(dropped) for name in src.namelist()):
        sys.exit(0)  # stripped before
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

# Every member of 1 MiB or more (ray's gcs_server, raylet and _raylet.so above all) recompressed with
# LZMA, a compression method of the zip format that pip reads as it reads deflate (Python's zipfile):
# the same bytes installed, 10 MiB less to carry (ray: 41.6 -> 31.5 MiB). A few minutes, once: a wheel
# whose large members are LZMA already is left as it is. The GPU machine's Python needs its lzma module
# to install them (scripts/device_check.sh checks it first).
"$python_bin" - "$dir" <<'EOF'
import os
import sys
import zipfile

folder = sys.argv[1]
for name in sorted(os.listdir(folder)):
    if not name.endswith(".whl"):
        continue
    path = os.path.join(folder, name)
    with zipfile.ZipFile(path) as src:
        large = [i for i in src.infolist() if i.file_size >= 2**20]
        if not large or all(i.compress_type == zipfile.ZIP_LZMA for i in large):
            continue
        packed = path + ".lzma"
        with zipfile.ZipFile(packed, "w") as dst:
            for item in src.infolist():
                copy = zipfile.ZipInfo(item.filename, item.date_time)
                copy.external_attr = item.external_attr  # the executable bits of ray's binaries
                copy.compress_type = zipfile.ZIP_LZMA if item.file_size >= 2**20 else zipfile.ZIP_DEFLATED
                dst.writestr(copy, src.read(item.filename))
    before, after = os.path.getsize(path), os.path.getsize(packed)
    os.replace(packed, path)
    print(f"recompressed {name}: {before / 2**20:.1f} -> {after / 2**20:.1f} MiB")
EOF

# The manifest: every wheel's name and size, tracked, so that `scripts/device_tree.py size` counts the
# wheels in a checkout that has not gathered them (and the import guard of a rehearsal knows their names).
"$python_bin" - "$dir" "${wheels[@]}" <<'EOF'
import json
import os
import sys

folder, wanted = sys.argv[1], sys.argv[2:]
files = sorted(f for f in os.listdir(folder) if f.endswith(".whl"))
wheels = [{"file": f, "bytes": os.path.getsize(os.path.join(folder, f))} for f in files]
total = sum(w["bytes"] for w in wheels)
manifest = {
    "what": "the wheels scripts/gather_device_wheels.sh puts in device_wheels/ for the GPU machine (which "
    "lacks them); scripts/device_tree.py size counts them from here where they are not gathered",
    "requirements": wanted,
    "wheels": wheels,
    "total_bytes": total,
}
with open("scripts/device_wheels.json", "w") as f:
    json.dump(manifest, f, indent=1)
    f.write("\n")
for w in wheels:
    print(f"{w['bytes'] / 2**20:8.1f} MiB  {w['file']}")
print(f"{total / 2**20:8.1f} MiB  in all (limit 64 MiB with everything else that travels: "
      "python3 scripts/device_tree.py size)")
sys.exit(1 if total > 64 * 2**20 else 0)
EOF
