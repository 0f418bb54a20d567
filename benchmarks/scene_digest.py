"""Every scene on a tiny set-up, run through the CLI of one checkout, its result.json kept without wall
times: a before/after check that a change leaves every scene's results the same bits.

    python benchmarks/scene_digest.py TREE OUTDIR [SCENE ...]     # run the scenes of checkout TREE
    python benchmarks/scene_digest.py compare OUTDIR_A OUTDIR_B    # which scenes differ (exit: how many)

Timing figures (particle-steps/s, "N s stepping", wall times) are left out of the comparison; every
measured value, reference and parameter is compared to the bit.  The CLI is this Python's
``python -m clusterdyn.cli`` with PYTHONPATH=TREE."""
import json
import os
import pathlib
import re
import subprocess
import sys

TINY = {
    "shock": {"size": "40x4x4", "fit_from": "0"},
    "plate-impact": {"flyer": "10", "target": "20", "width": "6", "frames": "20", "grain_size": "5",
                     "relax_cycles": "3", "sample": "single"},
    "polycrystal-shock": {"length": "30", "width": "6", "grain_size": "5", "frames": "15", "porosity": "0.15"},
    "mca-tension": {"size": "10x4x4", "steps": "300"},
    "mca-compression": {"size": "10x4x4", "steps": "300"},
    "dusting": {"length": "0.3mm", "frames": "12", "u": "4km/s", "J": "none"},
    "spall": {"sample": "single", "flyer": "8", "target": "16", "width": "4", "frames": "60"},
    "taylor": {"L0": "23.47mm", "V": "373", "r0": "1.27mm", "relax_cycles": "2", "t_max": "40"},
    "hypervelocity": {"r0": "0.8mm", "radius": "12mm", "t_end": "3"},
    "multilayer": {"r0": "2.5mm", "radius": "15mm", "t_end": "8"},
    "ejecta": {"r0": "1um", "rz": "6um", "wavelength": "16um", "n_periods": "1", "depth": "30um",
               "t_end": "0.018us", "frames": "6", "probes": "6", "snapshot_every": "0.009us",
               "spectrum_time": "0.018us", "pressure": "15GPa"},
    "jets": {"r0": "20um", "amplitude": "0.08mm", "wavelength": "0.64mm", "depth": "0.5mm",
             "t_end": "0.12us", "frames": "12", "probes": "8"},
    "mca-friction": {},
}


def strip(o):
    if isinstance(o, dict):
        return {k: strip(v) for k, v in o.items() if "wall" not in k and "time_s" not in k
                and k not in ("elapsed", "compile_s", "version", "out", "wrote", "files")}
    if isinstance(o, list):
        return [strip(v) for v in o]
    return o


def main(tree, outdir):
    out = pathlib.Path(outdir); out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=tree)
    exe = [sys.executable, "-m", "clusterdyn.cli"]
    names = sys.argv[3:] or list(TINY)
    for name in names:
        args = exe + ["run", name, "--json", "--quiet", "--out", str(out / ("run_" + name))]
        for k, v in TINY[name].items():
            args += ["--set", f"{k}={v}"]
        p = subprocess.run(args, env=env, capture_output=True, text=True, cwd=tree)
        if p.returncode:
            (out / f"{name}.err").write_text(p.stderr[-3000:])
            print(name, "FAILED", p.stderr.strip().splitlines()[-1:] if p.stderr else "")
            continue
        d = json.loads(p.stdout)
        (out / f"{name}.json").write_text(json.dumps(strip(d), indent=1, sort_keys=True))
        print(name, "ok", flush=True)




_TIMING = [re.compile(r"[\d.e+-]+ particle-steps/s"), re.compile(r"[\d.]+ s stepping"),
           re.compile(r"[\d.e+-]+ automaton-steps/s"), re.compile(r"in [\d.]+ s\b"), re.compile(r"stepping [\d.]+ s")]


def norm(o):
    if isinstance(o, dict):
        return {k: norm(v) for k, v in o.items() if "per_s" not in k}
    if isinstance(o, list):
        return [norm(v) for v in o]
    if isinstance(o, str):
        for r in _TIMING:
            o = r.sub("<t>", o)
    return o


def compare(a, b):
    bad = 0
    for fa in sorted(pathlib.Path(a).glob("*.json")):
        fb = pathlib.Path(b) / fa.name
        if not fb.exists():
            print("missing", fa.name); bad += 1; continue
        ra, rb = norm(json.loads(fa.read_text())), norm(json.loads(fb.read_text()))
        pa, pb = ra.get("params", {}), rb.get("params", {})
        for r in (ra, rb):      # parameters one side does not have yet (added by the change) are not results
            r["params"] = {k: v for k, v in r.get("params", {}).items() if k in pa and k in pb}
        same = ra == rb
        print(("same     " if same else "DIFFERENT"), fa.stem)
        bad += not same
    return bad


if __name__ == "__main__":
    if sys.argv[1] == "compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    main(sys.argv[1], sys.argv[2])
