"""Continue a stopped deck of :mod:`clusterdyn.io.lammps.export` from its last LAMMPS restart file.

A deck written with ``restart_every`` leaves ``restart.STEP`` files as it runs.  :func:`write_resume`
picks the newest whole one (:func:`latest_restart`), cuts every dump of the folder after its frame at
that step (:func:`cut_dump`: the frames up to it are the stopped run's and stay; the continuation
appends from the next step on, so no frame is written twice) and writes the continuation deck
``in.resume.cd`` (:func:`clusterdyn.io.lammps.export.deck_lines` with ``resume``): the same lines as
the first deck after ``read_restart``, and the runs from the restart step to the deck's end, the
region's removal loop resumed at its block.  :func:`clusterdyn.io.lammps.run.run_lammps` runs it with
``resume=STEP`` (log ``log.resume.STEP.lammps``); :func:`clusterdyn.io.lammps.run.read_run` reads the
folder back as one run.
"""

import mmap
import os
import re
from pathlib import Path

from ...errors import InputError
from .export import INPUT_FILE, deck_lines

__all__ = ["RESUME_FILE", "RESTART_MAGIC", "restart_steps", "restart_complete", "latest_restart", "cut_dump",
           "write_resume", "resume_log", "resumable"]

#: the continuation deck
RESUME_FILE = "in.resume.cd"

#: LAMMPS writes this at the start and at the end of a restart file: a file without it at its end was
#: stopped while being written
RESTART_MAGIC = b"LammpS RestartT\0"

_KEY = b"ITEM: TIMESTEP\n"


def resume_log(step):
    """The log of the continuation from the restart file at ``step``."""
    return f"log.resume.{int(step)}.lammps"


def restart_steps(folder):
    """Steps of the folder's ``restart.STEP`` files, newest first."""
    out = []
    for p in Path(folder).glob("restart.*"):
        m = re.fullmatch(r"restart\.(\d+)", p.name)
        if m:
            out.append(int(m.group(1)))
    return sorted(out, reverse=True)


def restart_complete(path):
    """True if the restart file ends with LAMMPS' closing magic string (it was written whole)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            if fh.tell() < 2 * len(RESTART_MAGIC):
                return False
            fh.seek(-len(RESTART_MAGIC), os.SEEK_END)
            return fh.read() == RESTART_MAGIC
    except OSError:
        return False


def _frames_backwards(mm):
    """(offset, step) of a dump's frames from the last to the first."""
    pos = mm.rfind(_KEY)
    while pos >= 0:
        nl = mm.find(b"\n", pos + len(_KEY))
        yield pos, int(mm[pos + len(_KEY):nl if nl >= 0 else len(mm)])
        pos = mm.rfind(_KEY, 0, pos)


def _whole_frame(mm, pos, end):
    """True if the frame at ``pos`` (to ``end``) has all the rows its header announces."""
    head = mm[pos:min(end, pos + 4096)].split(b"\n")
    try:
        n = int(head[3])
    except (IndexError, ValueError):
        return False
    return mm[pos:end].count(b"\n") == 9 + n


def _frame_at(path, step):
    """(offset, end) of the dump's whole frame at ``step`` or None."""
    path = Path(path)
    if not path.is_file() or path.stat().st_size == 0:
        return None
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        end = len(mm)
        for pos, st in _frames_backwards(mm):
            if st == step:
                return (pos, end) if _whole_frame(mm, pos, end) else None
            if st < step:
                return None
            end = pos
    return None


def latest_restart(folder):
    """The newest restart step of the folder whose file is whole and whose frame frames.dump has
    whole (a continuation starts on a dumped frame), or None."""
    folder = Path(folder)
    for step in restart_steps(folder):
        if not restart_complete(folder / f"restart.{step}"):
            continue
        if (folder / "frames.dump").is_file() and _frame_at(folder / "frames.dump", step) is None:
            continue
        return step
    return None


def cut_dump(path, step):
    """Cut a dump after its last frame at or before ``step``; returns the number of bytes cut."""
    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        return 0
    cut = size
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        for pos, st in _frames_backwards(mm):
            if st <= step:
                break
            cut = pos
    if cut < size:
        os.truncate(path, cut)
    return size - cut


def resumable(folder):
    """The restart step a continuation of the folder starts from (:func:`latest_restart`); refused in one
    line naming the folder when there is none."""
    step = latest_restart(folder)
    if step is None:
        why = ("none written" if not restart_steps(folder) else
               "none whole with its frame in frames.dump")
        raise InputError("DIR", str(folder), f"a stopped LAMMPS run with a restart file restart.STEP ({why}; "
                         "the deck writes them with restart_every)")
    return step


def _write_forces(dump, step, prefix):
    """The forces of the dump's frame at ``step`` as three LAMMPS ``atomfile`` files ``PREFIXx`` etc.
    ("id value" lines, the dump's own text: no rounding)."""
    pos, end = _frame_at(dump, step)
    with open(dump, "rb") as fh:
        fh.seek(pos)
        lines = fh.read(end - pos).decode().split("\n")
    cols = lines[8].split()[2:]
    n = int(lines[3])
    rows = [ln.split() for ln in lines[9:9 + n]]
    i = cols.index("id")
    for ax in "xyz":
        k = cols.index(f"f{ax}")
        text = "".join(f"{r[i]} {r[k]}\n" for r in rows)
        Path(f"{prefix}{ax}").write_text(f"# forces f{ax} at step {step} (eV/Angstrom), from {dump.name}\n{n}\n"
                                         + text)


def write_resume(atoms, calc, dyn, folder, **deck):
    """Write the continuation of a stopped deck from its newest whole restart file; returns its step.

    ``atoms``, ``calc``, ``dyn`` and ``deck`` (the keyword arguments of
    :func:`~clusterdyn.io.lammps.export.export_lammps` that wrote the folder's deck): the deck they write
    must be the folder's ``in.cd``, line for line, else refused.  Refused in one line naming the folder:
    no ``in.cd``, a different deck, no whole restart file.  With pair damping the run's forces at the
    restart step are written to ``restart.STEP.fx``, ``.fy``, ``.fz`` (the continuation's first forces:
    :func:`~clusterdyn.io.lammps.export.deck_lines`)."""
    folder = Path(folder)
    deck.pop("extra", None)
    if not (folder / INPUT_FILE).is_file():
        raise InputError("DIR", str(folder), f"a LAMMPS deck folder ({INPUT_FILE})")
    first, info = deck_lines(atoms, calc, dyn, **deck)
    have = (folder / INPUT_FILE).read_text().splitlines()
    if have != first:
        k = next((i for i, (a, b) in enumerate(zip(have, first)) if a != b), min(len(have), len(first)))
        raise InputError("DIR", str(folder), "a deck of this scene with these parameters (its "
                         f"{INPUT_FILE} differs from the rebuilt deck at line {k + 1})")
    step = resumable(folder)
    for p in sorted(folder.glob("*.dump")):
        cut_dump(p, step)
    forces = None
    if info.J is not None and (folder / "frames.dump").is_file():
        forces = f"restart.{step}.f"
        _write_forces(folder / "frames.dump", step, folder / forces)
    lines, _ = deck_lines(atoms, calc, dyn, resume=step, resume_forces=forces, **deck)
    (folder / RESUME_FILE).write_text("\n".join(lines) + "\n")
    return step
