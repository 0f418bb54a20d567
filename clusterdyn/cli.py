"""The ``clusterdyn`` command::

    clusterdyn run SCENE [--set key=value ...] [--config FILE.toml] [--out DIR] [--json] [--quiet]
                         [--restart CHECKPOINT] [--engine numba|lammps [--ranks N] [--deck-only] [--resume]]
    clusterdyn analyse SCENE DIR      (a --engine lammps folder whose decks have run)
    clusterdyn study STUDY [--set key=value ...] [--out DIR] [--json]
    clusterdyn list
    clusterdyn materials
    clusterdyn info FILE.h5md
    clusterdyn export lammps SCENE [--set ...] --out DIR

Bad input gives one clear line on stderr and exit status 2; a run that goes
unstable gives one line naming step, particles and quantity and exit status 3;
a file that cannot be written (full disk, no permission) or a machine without
the memory a run needs gives one line and exit status 1 (the last checkpoint
and the H5MD frames already written are kept); SIGINT (Ctrl-C) stops a run or
a study with "interrupted" and exit status 130, the last checkpoint kept.
A second run writing the same ``--out`` folder as a running one is refused.
"""

import argparse
import contextlib
import errno
import json
import os
import signal
import sys
from pathlib import Path

from . import __version__
from ._openmp import configure_openmp
from .errors import DEFER_INTERRUPT, INTERRUPTED, InputError, InstabilityError, OutputError

EXIT_OUTPUT = 1
EXIT_INPUT = 2
EXIT_INSTABILITY = 3
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError("command line", " ".join(sys.argv[1:]), f"valid arguments ({message})")


def _parse_sets(items):
    out = {}
    for it in items or []:
        if "=" not in it:
            raise InputError("--set", it, "key=value (e.g. u=3km/s)")
        k, v = it.split("=", 1)
        k = k.strip()
        if not k:
            raise InputError("--set", it, "key=value (e.g. u=3km/s)")
        out[k] = v.strip()
    return out


def _read_config(path):
    import tomllib
    p = Path(path)
    if not p.is_file():
        raise InputError("--config", str(path), "an existing TOML file")
    try:
        data = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError("--config", str(path), f"valid TOML ({exc})") from None
    params = data.get("params", data)
    if not isinstance(params, dict):
        raise InputError("--config", str(path), "a table of key = value parameters")
    if "params" in data:
        extra = [k for k in data if k not in ("scene", "params")]
        if extra:
            raise InputError("--config", f"{path}: {extra[0]}", "top-level keys scene and [params] only "
                             "(parameters go in [params])")
    out = {}
    for k, v in params.items():
        if isinstance(v, dict):
            raise InputError("--config", f"{k} (a table)", "key = value parameters")
        out[k] = v if not isinstance(v, list) else "x".join(str(x) for x in v)
    return out, data.get("scene")


def _print_result(res, args):
    if args.json:
        print(res.to_json())
    elif not args.quiet:
        print(f"\n{res.scene}: results")
        print(res.table())
        for f in res.files:
            print(f"wrote {f}")
    for w in res.warnings:      # one line each on stderr, also with --json and --quiet
        print(f"clusterdyn: warning: {w}", file=sys.stderr)


def _threads(args):
    """``--threads N``: the kernels' thread limit for this run (default: numba's, NUMBA_NUM_THREADS)."""
    if args.threads is not None:
        from .parallel import set_max_threads
        set_max_threads(args.threads)


def _print_run_help(scene_name, parser):
    """``clusterdyn run --help`` (the scenes) or ``clusterdyn run SCENE --help`` (its parameters),
    then the options as argparse describes them."""
    from .scenes import all_scenes, get_scene
    if scene_name is None:
        print("scenes (clusterdyn run SCENE --help gives a scene's parameters):")
        for name, sc in sorted(all_scenes().items()):
            print(f"  {name:18s} {sc.description}")
    else:
        sc = get_scene(scene_name)
        print(f"{scene_name}: {sc.description}\n")
        print("parameters (--set KEY=VALUE; default, unit, meaning, range):")
        for p in sc.params:
            print(f"  {p.describe()}")
    print()
    print(parser.format_help())
    return 0


def cmd_run(args):
    from .scenes import get_scene
    from .scenes.base import display_text
    if args.help or args.scene is None:
        code = _print_run_help(args.scene, args.run_parser)
        return code if args.help else EXIT_INPUT
    _threads(args)
    overrides = {}
    scene = get_scene(args.scene)
    if args.config:
        cfg, scene_name = _read_config(args.config)
        if scene_name and scene_name != args.scene:
            raise InputError("--config", args.config, f"a config for scene '{args.scene}' (it is for '{scene_name}')")
        known = [p.name for p in scene.params]
        for k in cfg:
            if k not in known:
                raise InputError("--config", f"{args.config}: {k}", f"a parameter of scene '{scene.name}': "
                                 + ", ".join(known))
        overrides.update(display_text(scene, cfg))      # a TOML number is in the display unit, as on the CLI
    overrides.update(_parse_sets(args.set))
    kw = {}
    if args.restart:
        kw["restart"] = args.restart
        if not Path(args.restart).is_file():
            raise InputError("--restart", args.restart, "an existing checkpoint file")
    out = Path(args.out) if args.out else None
    if args.engine == "lammps":
        return _run_lammps(args, overrides, out)
    if args.resume:
        raise InputError("--resume", "--resume", "only with --engine lammps (a numba run continues with "
                         "--restart CHECKPOINT)")
    if args.ranks is not None or args.deck_only:
        raise InputError("--ranks/--deck-only", args.ranks if args.ranks is not None else "--deck-only",
                         "only with --engine lammps")
    res = scene.run(overrides, out=out, progress=not args.quiet, **kw)   # bars on stderr, also with --json
    _print_result(res, args)
    return 0


def _run_lammps(args, overrides, out):
    from .scenes.lammps_engine import analyse_command, resume_scene_lammps, run_command, run_scene_lammps
    if args.restart:
        raise InputError("--restart", args.restart, "no --restart with --engine lammps (LAMMPS writes no "
                         "clusterdyn checkpoints: --resume continues the run in --out from its LAMMPS "
                         "restart files)")
    ranks = 1 if args.ranks is None else args.ranks
    if args.resume:
        got = resume_scene_lammps(args.scene, overrides, out, ranks=ranks, deck_only=args.deck_only,
                                  progress=not args.quiet)
        if not args.deck_only:
            _print_result(got, args)
            return 0
        cmds = [run_command(f, ranks, resume=step) for f, step in got]
        if args.json:
            print(json.dumps({"decks": [str(f) for f, _ in got], "run": cmds,
                              "analyse": analyse_command(args.scene, out)}))
        elif not args.quiet:
            for (f, step), cmd in zip(got, cmds):
                what = "its first deck" if step is None else f"the continuation from restart.{step}"
                print(f"wrote {what} in {f}; run it with: {cmd}")
            print(f"then analyse its dumps with: {analyse_command(args.scene, out)}")
        return 0
    got = run_scene_lammps(args.scene, overrides, out, ranks=ranks, deck_only=args.deck_only,
                           progress=not args.quiet)     # on stderr, also with --json
    if args.deck_only:
        if args.json:
            print(json.dumps({"decks": [str(f) for f in got], "run": [run_command(f, ranks) for f in got],
                              "analyse": analyse_command(args.scene, out)}))
        elif not args.quiet:
            for f in got:
                print(f"wrote LAMMPS deck to {f}; run it with: {run_command(f, ranks)}")
            print(f"then analyse its dumps with: {analyse_command(args.scene, out)}")
        return 0
    _print_result(got, args)
    return 0


def cmd_analyse(args):
    from .scenes.lammps_engine import analyse_scene
    res = analyse_scene(args.scene, args.dir)
    _print_result(res, args)
    return 0


def cmd_study(args):
    from .studies import get_study, study_names, study_params, study_summary
    if args.study is None:
        print("usage: clusterdyn study STUDY [--set KEY=VALUE ...] [--out DIR] [--json] [--quiet]\n\n"
              "studies (clusterdyn study STUDY --help gives a study's parameters):")
        for name in study_names():
            print(f"  {name:22s} {study_summary(name)}")
        return 0 if args.help else EXIT_INPUT
    if args.help:
        study = get_study(args.study)
        print(f"{args.study}: {study_summary(args.study)}")
        print("parameters (--set key=value):")
        for p in study_params(args.study):
            print(f"    {p.describe()}")
        return 0
    _threads(args)
    study = get_study(args.study)
    out = Path(args.out) if args.out else None
    from .scenes.lifecycle import check_out, lock_out
    with lock_out(check_out(out)):
        res = study(_parse_sets(args.set), out=out, progress=not (args.quiet or args.json))
    if args.json:
        print(json.dumps(res, default=str))
    return 0


def cmd_list(args):
    from .scenes import all_scenes
    from .studies import study_names, study_params, study_summary
    print("scenes (clusterdyn run SCENE --set key=value ...):")
    for name, sc in sorted(all_scenes().items()):
        print(f"  {name}: {sc.description}")
        for p in sc.params:
            print(f"      {p.describe()}")
    print("studies (clusterdyn study STUDY --set key=value ...; clusterdyn study STUDY --help):")
    for name in study_names():
        print(f"  {name}: {study_summary(name)}")
        for p in study_params(name):
            print(f"      {p.describe()}")
    return 0


def cmd_materials(args):
    from . import units
    from .materials import get_material, material_names
    for name in material_names():
        m = get_material(name)
        line = f"{name}: rho0 = {m.rho0 / units.g_cm3:g} g/cm3"
        if m.curve is not None:
            line += f", c0 = {m.c0 / units.km_s:.4g} km/s, cold curve {type(m.curve).__name__}"
            if hasattr(m.curve, "n_tail"):
                lo, hi = m.curve.tail_slopes
                line += (f" ({m.curve.tail} tail beyond delta = {m.curve.delta_rows[-1]:.4g}: n = "
                         f"{m.curve.n_tail:.4g}, A = {m.curve.A_tail / units.GPa:.4g} GPa; dP/d delta "
                         f"{lo / units.GPa:.0f} -> {hi / units.GPa:.0f} GPa)")
            elif hasattr(m.curve, "n"):
                line += f" (n = {m.curve.n:.4g})"
        if m.E is not None:
            line += f", E = {m.E / units.GPa:g} GPa, nu = {m.nu:g}"
        if m.hugoniot:
            line += f", reference Hugoniot {m.hugoniot}"
        print(line)
        print(f"    source: {m.source}")
    return 0


def cmd_info(args):
    p = Path(args.file)
    if not p.is_file():
        raise InputError("FILE", args.file, "an existing H5MD file")
    from .io import format_info
    print(format_info(str(p)))
    return 0


def cmd_export(args):
    if args.format != "lammps":
        raise InputError("format", args.format, "lammps")
    from .scenes.export import export_scene
    folders = export_scene(args.scene, _parse_sets(args.set), args.out)
    if not args.quiet:
        for folder in folders:
            print(f"wrote LAMMPS deck to {folder}")
    return 0


def build_parser():
    p = _Parser(prog="clusterdyn", description="Cluster Dynamics and Movable Cellular Automata")
    p.add_argument("--version", action="version", version=f"clusterdyn {__version__}")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    r = sub.add_parser("run", help="run a scene (clusterdyn run --help lists them)", add_help=False)
    r.add_argument("scene", nargs="?")
    r.add_argument("--help", "-h", action="store_true", help="the scenes, or a scene's parameters")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="a scene parameter, with its unit (u=3km/s, r0=5um); repeat for more")
    r.add_argument("--config", metavar="FILE.toml",
                   help="parameters from a TOML file (top-level 'scene' and a [params] table)")
    r.add_argument("--out", metavar="DIR",
                   help="the folder for result.json, the H5MD file, PNG, CSV and the checkpoint")
    r.add_argument("--json", action="store_true",
                   help="print the result as one JSON object on stdout (the progress bar stays on stderr)")
    r.add_argument("--quiet", action="store_true", help="no table and no progress bar")
    r.add_argument("--restart", metavar="CHECKPOINT",
                   help="continue a run from its checkpoint.h5 (same parameters)")
    r.add_argument("--threads", type=int, metavar="N", help="threads of the kernels (default: all; "
                   "one is faster on a machine busy with other jobs)")
    r.add_argument("--engine", choices=("numba", "lammps"), default="numba",
                   help="numba: clusterdyn's own kernels (default); lammps: the scene's deck run by LAMMPS "
                   "(docs/lammps.md), its dumps analysed by the scene")
    r.add_argument("--ranks", type=int, metavar="N", help="MPI ranks of the LAMMPS run (--engine lammps; "
                   "default 1)")
    r.add_argument("--deck-only", action="store_true", help="--engine lammps: write the decks and the command "
                   "that analyses their dumps later (clusterdyn analyse SCENE DIR), run nothing")
    r.add_argument("--resume", action="store_true", help="--engine lammps: continue the stopped run in --out from "
                   "its last LAMMPS restart files, then analyse it (with --deck-only: write the continuation decks)")
    r.set_defaults(func=cmd_run, run_parser=r)
    an = sub.add_parser("analyse", help="a scene's analysis and report from the dumps of its LAMMPS decks")
    an.add_argument("scene")
    an.add_argument("dir")
    an.add_argument("--json", action="store_true")
    an.add_argument("--quiet", action="store_true")
    an.set_defaults(func=cmd_analyse)
    s = sub.add_parser("study", help="run a study (clusterdyn study --help lists them)", add_help=False)
    s.add_argument("study", nargs="?")
    s.add_argument("--help", "-h", action="store_true", help="the study's parameters")
    s.add_argument("--set", action="append", metavar="KEY=VALUE")
    s.add_argument("--out", metavar="DIR")
    s.add_argument("--json", action="store_true")
    s.add_argument("--quiet", action="store_true")
    s.add_argument("--threads", type=int, metavar="N", help="threads of the kernels (default: all)")
    s.set_defaults(func=cmd_study)
    sub.add_parser("list", help="scenes and their parameters").set_defaults(func=cmd_list)
    sub.add_parser("materials", help="the material library").set_defaults(func=cmd_materials)
    i = sub.add_parser("info", help="summary of an H5MD file")
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    e = sub.add_parser("export", help="export a scene to another code")
    e.add_argument("format")
    e.add_argument("scene")
    e.add_argument("--set", action="append", metavar="KEY=VALUE")
    e.add_argument("--out", metavar="DIR", required=True)
    e.add_argument("--quiet", action="store_true")
    e.set_defaults(func=cmd_export)
    return p


def _on_sigint(signum, frame):
    """SIGINT: remember it; a run stepping stops at its next step (errors.DEFER_INTERRUPT), anything
    else (and a second SIGINT) raises KeyboardInterrupt at once, as Python's own handler does."""
    again = INTERRUPTED[0]
    INTERRUPTED[0] = True
    if again or not DEFER_INTERRUPT[0]:
        raise KeyboardInterrupt


@contextlib.contextmanager
def _sigint_handler():
    try:
        prev = signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:                  # not the main thread: leave signals alone
        yield
        return
    INTERRUPTED[0] = False
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, prev)
        INTERRUPTED[0] = False          # the flag belongs to this handler's run: later work in the process starts clean


def _interrupted():
    from .scenes.lifecycle import LAST_CHECKPOINT
    msg = "clusterdyn: interrupted"
    if LAST_CHECKPOINT.get("path") and os.path.exists(LAST_CHECKPOINT["path"]):
        msg += (f"; the last checkpoint ({LAST_CHECKPOINT['path']}, step {LAST_CHECKPOINT['step']}) is kept: "
                f"continue with --restart {LAST_CHECKPOINT['path']}")
    print(msg, file=sys.stderr)
    return EXIT_INTERRUPTED


_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO)


def main(argv=None):
    configure_openmp()          # before numba's OpenMP runtime starts (clusterdyn.parallel)
    with _sigint_handler():
        try:
            code = _main(argv)
        except KeyboardInterrupt:
            return _interrupted()
        except SystemError:
            if INTERRUPTED[0]:          # the interrupt raised inside a compiled callback (numba, h5py)
                return _interrupted()
            raise
        if INTERRUPTED[0]:              # an interrupt some library swallowed: still not a success
            return _interrupted()
        return code


def _main(argv=None):
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if not getattr(args, "command", None):
            parser.print_help()
            return EXIT_INPUT
        return args.func(args)
    except BrokenPipeError:
        # the reader of our output went away (clusterdyn list | head): stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OutputError as exc:
        print(f"clusterdyn: error: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    except MemoryError as exc:
        print(f"clusterdyn: error: not enough memory for this run ({exc or 'an allocation failed'}); "
              "choose a smaller sample", file=sys.stderr)
        return EXIT_OUTPUT
    except OSError as exc:
        if exc.errno not in _WRITE_ERRNOS:
            raise
        where = f" {exc.filename}" if exc.filename else ""
        print(f"clusterdyn: error: cannot write{where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_OUTPUT
    except InputError as exc:
        print(f"clusterdyn: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except InstabilityError as exc:
        print(f"clusterdyn: unstable: {exc}", file=sys.stderr)
        return EXIT_INSTABILITY


if __name__ == "__main__":
    sys.exit(main())
