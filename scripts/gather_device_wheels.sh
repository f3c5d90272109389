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
"$python_bin" -m pip download --disable-pip-version-check --quiet --no-deps --dest "$dir" \
  --python-version 3.12 --implementation cp --abi cp312 --only-binary=:all: \
  --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux_2_28_x86_64 \
  "${wheels[@]}"

# Strip ray's jars, dashboard page, Serve and LLM libraries (none of which a trial imports), and their lines in the wheel's RECORD (pip checks every file
# it installs against RECORD; a file that is not there is simply not installed).
# Idempotent: a wheel stripped before is copied as it is.
ray_wheel="$(ls "$dir"/ray-2.60.0-*.whl)"
"$python_bin" - "$ray_wheel" <<'EOF'
import os
import sys
import zipfile

path = sys.argv[1]
dropped = ("ray/jars/", "ray/dashboard/client/", "ray/serve/", "ray/llm/")
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
