"""Drive surfsynth from Python: run a config with subprocess, read metrics.json.

    cargo install --path .          # puts `surfsynth` on PATH
    python3 examples/run_from_python.py configs/00_default.toml

Set SURFSYNTH to the executable's path to use another build
(e.g. SURFSYNTH=target/release/surfsynth).
"""

import json
import os
import pathlib
import subprocess
import sys
import tempfile


def run(config, out_dir, overrides=()):
    """Runs `config` into `out_dir` and returns the parsed metrics.json."""
    exe = os.environ.get("SURFSYNTH", "surfsynth")
    cmd = [exe, "run", str(config), "--out", str(out_dir), "--quiet"]
    for o in overrides:
        cmd += ["--set", o]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        # Exit 2: bad input, the message names what to fix; 1: internal error.
        raise RuntimeError(f"surfsynth exited {done.returncode}: {done.stderr.strip()}")
    return json.loads((pathlib.Path(out_dir) / "metrics.json").read_text())


if __name__ == "__main__":
    config = sys.argv[1] if len(sys.argv) > 1 else "configs/00_default.toml"
    with tempfile.TemporaryDirectory() as out:
        metrics = run(config, out, overrides=sys.argv[2:])
        quality = metrics["result"]["quality"]
        print("completeness:", quality.get("completeness"))
        print("seconds:", round(metrics["total_seconds"], 3))
        for stage in metrics["stages"]:
            print(f"stage {stage['index']} {stage['kind']}: {stage['seconds']:.3f} s")
