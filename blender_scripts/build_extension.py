"""Builds the installable Blender extension zip (README: `make addon`): the add-on's Python
files, its manifest with the native module's wheel listed under `wheels`, and that wheel.

Run: .venv/bin/python blender_scripts/build_extension.py [--out dist]
"""

from __future__ import annotations

import argparse
import pathlib
import re
import subprocess
import sys
import tempfile
import zipfile

REPO = pathlib.Path(__file__).resolve().parents[1]


def build_wheel(out: pathlib.Path) -> pathlib.Path:
    out.mkdir(parents=True, exist_ok=True)
    # The interpreter `make build` (maturin develop) builds for: PyO3 rebuilds itself and the
    # binding crate whenever PYO3_PYTHON changes, so another one costs a minute each way.
    subprocess.run(
        [sys.executable, "-m", "maturin", "build", "--release", "--quiet", "--out", str(out),
         "--interpreter", sys.executable, "--manifest-path", str(REPO / "rust" / "python" / "Cargo.toml")],
        check=True, cwd=REPO,
    )
    wheels = sorted(out.glob("translucent-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        raise SystemExit("maturin produced no wheel")
    return wheels[-1]


def build_zip(wheel: pathlib.Path, out: pathlib.Path) -> pathlib.Path:
    manifest = (REPO / "addon" / "blender_manifest.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', manifest, re.M).group(1)
    manifest = re.sub(r"^# wheels = .*$", f'wheels = ["./wheels/{wheel.name}"]', manifest, flags=re.M)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"translucent-{version}.zip"
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("blender_manifest.toml", manifest)
        for py in sorted((REPO / "addon").glob("*.py")):
            z.write(py, py.name)
        z.write(wheel, f"wheels/{wheel.name}")
    return target


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(REPO / "dist"))
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    with tempfile.TemporaryDirectory() as tmp:
        wheel = build_wheel(pathlib.Path(tmp))
        target = build_zip(wheel, out)
    print(target)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
