"""Output folders written all at once: a run's files appear together or not at all.

:func:`check_out` refuses a bad ``--out`` before any work; :class:`OutputSet` writes a
command's files into a hidden sibling folder of ``--out`` and moves them in together, so
Ctrl-C, a full disk or a crash leaves the previous files untouched and two runs into one
folder leave one run's set, never a mix; :func:`atomic_file` does the same for one file
(--mcap, a study's results.parquet, a calibration). Every command's outputs go through them;
:func:`safe_name` makes a name one folder name, :func:`folder_name` the one no other name
gets (``out/<name>``); :func:`real_path` resolves a path that may be a loop of links.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import secrets
import shutil
import tempfile
import time
import unicodedata
from collections.abc import Iterator
from pathlib import Path

from .errors import OutputError, printable
from .safe_yaml import MCAP_MAGIC, input_kind, not_text

try:
    import fcntl
except ImportError:   # pragma: no cover - Windows: no advisory locks (sole_writer)
    fcntl = None

# every file `irring run/replay/drive` may write: a folder holding only these is ours to swap
RUN_FILES = frozenset({"map.png", "map_building.gif", "map.pgm", "map.yaml", "sweeps.npz",
                       "link.json", "map.mcap"})
_TEMP_PREFIX = ".irring-"


def real_path(path: str | Path) -> Path:
    """``path`` absolute, with links and ``..`` resolved as far as they go: a loop of links
    is left as it is (``Path.resolve`` raises RuntimeError on one before Python 3.13), so
    the check that follows names it as a path that does not exist."""
    return Path(os.path.realpath(path))


def safe_name(name: str, default: str = "scenario") -> str:
    """``name`` as a single folder name: letters, digits, ``._-`` kept, anything else
    (``/``, ``..``, control characters, spaces) replaced by ``_``; never empty, ``.`` or
    ``..``, at most 80 characters."""
    text = re.sub(r"[^A-Za-z0-9._-]+", "_", str(name))
    text = re.sub(r"_+", "_", re.sub(r"\.\.+", "_", text))
    return text[:80].strip("._") or default


# replay's folder is out/<run>-replay: no other name's folder ends so
REPLAY_SUFFIX = "-replay"
_PLAIN = re.compile(r"[a-z0-9._-]+")


def name_key(name: str) -> str:
    """What makes two names one name: the same text in any Unicode form (NFC and NFD of
    ``café`` are one name; ``Café`` and ``cafe`` are not)."""
    return unicodedata.normalize("NFC", str(name))


def folder_name(name: str, default: str = "scenario") -> str:
    """The folder of ``name`` (a scenario's, a study file's, a recording's) where a command
    writes without --out: ``name`` itself when it is :func:`safe_name`'s and only lower-case
    letters, digits and ``._-`` (not ending in ``-replay``), else its safe name, ``~`` and 8
    hex digits of its SHA-256. So two names never share a folder, even on a file system
    blind to case (``room`` and ``room 🏠``, ``room a`` and ``room_a``, ``Room`` and
    ``room``: safe_name makes each pair one); the Unicode forms of one name (NFC, NFD) are
    one name (``café``: ``cafe~850f7dc4``)."""
    text = name_key(name)
    if _PLAIN.fullmatch(text) and safe_name(text) == text and not text.endswith(REPLAY_SUFFIX):
        return text
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    ascii_ = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()  # é → e
    return f"{safe_name(ascii_, default)[:71]}~{digest}"


def folder_note(name: str, folder: str | Path, what: str, suffix: str = "") -> str | None:
    """The line that says why ``folder`` (:func:`folder_name` of ``what`` ``name``, then
    ``suffix``) is not the name itself; None when it is."""
    if Path(folder).name == f"{name}{suffix}":
        return None
    return (f"{printable(str(folder))}/ is the folder of {what} {printable(repr(str(name)))}: "
            "a name of other than lower-case letters, digits and ._- is written with ~ and 8 "
            "hex digits of its SHA-256, so no other name's outputs replace it")


def _replaceable(path: Path) -> bool:
    """A file (or a link) an output may replace; a folder, pipe or device is never replaced
    (the folder swap removed a folder ``map.png/`` and all it held)."""
    return path.is_symlink() or path.is_file() or not path.exists()


def _check_names(out: Path, files, option: str) -> None:
    """:class:`OutputError` when ``out`` holds one of ``files`` as a folder or other
    non-file, which the outputs would have to replace."""
    for name in sorted(files):
        path = out / name
        if not _replaceable(path):
            what = ("is a folder" if path.is_dir() else
                    "is not a regular file (a pipe, device or socket)")
            raise OutputError(f"{option} {printable(str(out))}: {name} there {what}; irring "
                              f"writes a file of that name and never replaces a "
                              f"{'folder' if path.is_dir() else 'non-file'}: move it away or "
                              "choose another --out")


def check_out(out: str | Path, option: str = "--out", *, held: bool = True,
              files=()) -> Path:
    """``out`` if it can become a folder of outputs: an existing writable folder, or a path
    whose nearest existing parent is a writable folder. ``held=False``: also refuse a folder
    another irring process holds (a study writing there) for :data:`PROBE_WAIT_S`, as an
    :class:`OutputSet` commit would after the work. ``files``: the names the command writes;
    one ``out`` holds as a folder (or other non-file) is refused before the work. Raises
    :class:`OutputError` naming the option."""
    out = Path(out)
    shown = printable(str(out))
    try:
        if out.exists() and not out.is_dir():
            raise OutputError(f"{option} {shown}: is a file; expected a folder for the outputs")
        probe = out
        while not probe.exists():
            # a dangling link here or above: the move into it failed after the work ("File
            # exists", for a link above --out)
            if probe.is_symlink():
                what = "is" if probe == out else f"{printable(str(probe))} is"
                raise OutputError(f"{option} {shown}: {what} a link to "
                                  f"{printable(os.readlink(probe))}, which does not exist (or a "
                                  "loop of links); make that folder or name another")
            if probe.parent == probe:
                break
            probe = probe.parent
    except OutputError:
        raise
    except OSError as exc:   # a name longer than the file system takes: exit 1 (bad input)
        raise OutputError(f"{option} {shown}: cannot be a folder: {_why(exc)}") from None
    if not probe.is_dir():
        raise OutputError(f"{option} {shown}: {printable(str(probe))} is a file, so the folder "
                          "cannot be made")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {shown}: {printable(str(probe))} is not writable")
    if probe == out:
        _check_names(out, files, option)
    if not held and probe == out:
        with _holding(out, PROBE_WAIT_S) as free:
            if not free:
                raise OutputError(f"{option} {shown}: another irring process holds the folder "
                                  f"(a study writing its results there?); nothing was run: "
                                  f"choose another --out, or run again when it is done")
    return out


class OutputSet:
    """The files of one run, written under :attr:`tmp` and moved into ``out`` by
    :meth:`commit`.

    ``files``: the names the command may write (default: :data:`RUN_FILES`). A previous
    run's file of these names that this run does not write is removed, so the folder holds
    one run's set; a folder holding only these names is swapped whole; other files in
    ``out`` (a study's results.csv, the user's own) are kept. Use as a context manager: on
    leaving without an exception the set is committed, on an exception (or Ctrl-C) the
    temporaries are removed and ``out`` is left as it was. Raises :class:`OutputError`.
    """

    def __init__(self, out: str | Path, option: str = "--out", files=RUN_FILES):
        self.out = check_out(out, option)
        self.option = option
        self.files = frozenset(files)
        self.tmp: Path | None = None
        self.made: list[Path] = []   # folders __enter__ made for ``out``, innermost first

    def __enter__(self) -> Path:
        self.made = []
        try:
            self.made = _make_folders(self.out.absolute().parent)
            try:
                self.tmp = _hidden_sibling(self.out.absolute(), folder=True)
            except OSError as exc:
                # a writable --out in a folder one may not write (a mount point under
                # /media/me): the set is written inside it, and each file renamed in
                if exc.errno not in _WRITE_ERRNOS or not self.out.is_dir():
                    raise
                self.tmp = _hidden_sibling(self.out.absolute() / "set", folder=True)
        except OSError as exc:
            _remove_empty(self.made)
            raise OutputError(f"{self.option} {printable(str(self.out))}: cannot write "
                              f"there: {exc.strerror or exc}") from None
        return self.tmp

    def __exit__(self, kind, exc, tb) -> None:
        if kind is None:
            try:
                self.commit()
            finally:
                self.discard()
        else:
            self.discard()
            _remove_empty(self.made)   # nothing written: no folders made for it either
            if (isinstance(exc, OSError) and not isinstance(exc, OutputError)
                    and exc.errno in _WRITE_ERRNOS):
                # a full disk or a file-size limit says neither folder nor file: name --out
                raise OutputError(f"{self.option} {printable(str(self.out))}: cannot write the "
                                  f"outputs there: {_why(exc)}; nothing was changed") from exc

    def discard(self) -> None:
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None

    def commit(self) -> None:
        """Move the written files into ``out``: the whole folder is swapped when ``out`` holds
        nothing but a run's files; otherwise each file is renamed in (after the work, each an
        atomic rename) and a previous run's files this run did not write are removed."""
        assert self.tmp is not None
        out = self.out
        try:
            if not out.exists():
                try:
                    os.rename(self.tmp, out)
                    self.tmp = None
                    return
                except OSError:
                    if not out.is_dir():
                        raise
            # one commit at a time: two runs renaming their files in one by one left a mix
            # (a map.pgm of one, sweeps.npz of the other)
            with _holding(out, COMMIT_WAIT_S) as held:
                if not held:
                    raise OutputError(
                        f"{self.option} {printable(str(out))}: another irring process held the "
                        f"folder for {COMMIT_WAIT_S:g} s (a study writing there?); nothing was "
                        "changed: choose another --out, or run again when it is done")
                self._move_in(out)
        except OutputError:
            raise
        except OSError as exc:
            raise OutputError(f"{self.option} {printable(str(out))}: cannot move the outputs "
                              f"in: {exc.strerror or exc}") from None


    def _move_in(self, out: Path) -> None:
        written = {p.name for p in self.tmp.iterdir()}
        _check_names(out, written, self.option)   # before anything is moved or removed
        if all(p.name in self.files and _replaceable(p) for p in out.iterdir()) \
                and self._swap():
            return
        for name in sorted(self.files - written):
            stale = out / name
            if stale.is_file():
                stale.unlink()
        for name in sorted(written):
            os.replace(self.tmp / name, out / name)

    def _swap(self) -> bool:
        """Replace the folder ``out`` by the written one; False when that cannot be done
        (``out`` is the working folder or a mount point, or another run got there first)."""
        out = self.out.absolute()
        if out == Path.cwd() or os.path.ismount(out):
            return False
        old = Path(tempfile.mkdtemp(prefix=f"{_TEMP_PREFIX}old-", dir=out.parent))
        try:
            os.rename(out, old / "previous")
        except OSError:
            shutil.rmtree(old, ignore_errors=True)
            return False
        try:
            os.rename(self.tmp, out)
            self.tmp = None
            return True
        except OSError:
            if not out.exists():
                os.rename(old / "previous", out)
            return False
        finally:
            shutil.rmtree(old, ignore_errors=True)


def _make_folders(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; the ones made, innermost first (a write
    that fails removes them again: a failed command leaves no empty folders behind)."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        _remove_empty(missing)
        raise
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (innermost first) while they are empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except FileNotFoundError:
            continue
        except OSError:   # not empty (another writer's files), or not ours to remove
            return


def _hidden_sibling(path: Path, *, folder: bool) -> Path:
    """A new, empty hidden file or folder beside ``path``, made with the modes any file the
    user makes gets (umask applied: tempfile's are private, and would stay so once renamed
    into place)."""
    for _ in range(100):
        tmp = path.parent / f"{_TEMP_PREFIX}{safe_name(path.name)}-{secrets.token_hex(4)}"
        try:
            if folder:
                os.mkdir(tmp, 0o777)
            else:
                os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


# an OSError of these while writing the temporary is the output's fault, not the writer's
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG, errno.EACCES,
                           errno.EPERM})


MCAP_FILE = "MCAP file"   # ``writes`` of an MCAP: it replaces nothing but an MCAP
CHART_FILE = "calibration chart"   # the picture irring calibrate writes beside its file
CHART_SOFTWARE = "irring calibrate"   # its PNG's Software field, which tells it
VIEW_FILE = "view picture"   # the picture irring view writes
VIEW_SOFTWARE = "irring view"   # its PNG's Software field
# view.png in view's own places (out/<scenario>/, an --out folder): view's by its name, so
# one drawn before the Software field named it (a PNG naming no program) is replaced too
VIEW_IN_FOLDER = "view picture in its folder"
# what each kind of file irring writes over an existing one (it replaces only its own kind)
_OWN_KIND = {MCAP_FILE: "an MCAP", CHART_FILE: "a calibration chart",
             VIEW_FILE: "a picture irring view drew",
             VIEW_IN_FOLDER: "a picture irring view drew",
             "calibration file": "a calibration file",
             "calibration progress file": "a calibration progress file"}
# the Software field of a PNG of each kind (a chart drawn before it named itself: matplotlib's)
_DRAWN_BY = {CHART_FILE: (CHART_SOFTWARE, "Matplotlib"), VIEW_FILE: (VIEW_SOFTWARE,),
             VIEW_IN_FOLDER: (VIEW_SOFTWARE,)}


def _drawn(path: Path, writes: str) -> bool:
    """A PNG whose Software field says irring drew it as ``writes`` (a key of _DRAWN_BY)."""
    from PIL import Image   # deferred: Pillow

    try:
        with Image.open(path) as im:
            made_by, fmt = str(im.info.get("Software", "")), im.format
    except Exception:   # not a picture Pillow reads
        return False
    return made_by.startswith(_DRAWN_BY[writes]) or (writes == VIEW_IN_FOLDER and
                                                     not made_by and fmt == "PNG")


def check_replaceable(path: str | Path, option: str | None = None,
                      writes: str | None = None) -> None:
    """:class:`OutputError` when ``path`` is an irring input file (a recording, scenario,
    study, calibration or progress file) of another kind than ``writes``: a slip of the
    path (``calibrate --out my_room.yaml``) replaced it. A file of a kind in ``_OWN_KIND``
    (an MCAP, a calibration, its chart, a progress file) replaces only one of its kind or an
    empty file: ``--mcap photo.png`` and ``calibrate --out notes.txt`` replaced them."""
    path = Path(path)
    found = input_kind(path) if path.is_file() else None
    shown = printable(f"{option} {path}" if option else str(path))
    if found is not None and found[0] != writes:
        raise OutputError(f"{shown}: is {found[1]}; writing there would replace it: name "
                          "another file")
    own = _OWN_KIND.get(writes)
    if own is None or not path.is_file():
        return
    try:
        with open(path, "rb") as f:
            head = f.read(64)
    except OSError:
        return   # unreadable: the write itself says why
    if not head or (head.startswith(MCAP_MAGIC) if writes == MCAP_FILE else
                    _drawn(path, writes) if writes in _DRAWN_BY else found is not None):
        return
    what = not_text(head) or "a file"
    rule = ("irring view replaces only a picture it drew, which names it in its PNG's "
            "Software field" if writes == VIEW_FILE else
            "in its folder irring view replaces only a PNG whose Software field names it, or "
            "names no program, as its pictures did before" if writes == VIEW_IN_FOLDER else
            f"{own} replaces only {own}")
    other = ("another folder, or a FILE.png" if writes == VIEW_IN_FOLDER else "another file")
    raise OutputError(f"{shown}: is {what}, not {own}; writing there would replace it ({rule}): "
                      f"name {other}")


@contextlib.contextmanager
def atomic_file(path: str | Path, option: str | None = None,
                writes: str | None = None) -> Iterator[Path]:
    """A hidden temporary file beside ``path`` to write, renamed over ``path`` when the
    block ends without an exception and removed when it ends with one: a reader (or the
    user after Ctrl-C, a full disk, a crash of the writer) sees the old file or the whole
    new one, never part of one. A missing parent folder is made. Raises
    :class:`OutputError` naming ``path`` (after ``option``, e.g. ``--mcap``, if given) when
    the folder cannot be made or written, ``path`` is a folder or a device (never replaced),
    or the disk fills."""
    path = Path(path)
    shown = printable(f"{option} {path}" if option else str(path))
    try:
        kind = "folder" if path.is_dir() else "other" if path.exists() and not path.is_file() \
            else None
    except OSError as exc:   # a name longer than the file system takes
        raise OutputError(f"{shown}: cannot be written: {_why(exc)}") from None
    if kind == "folder":
        raise OutputError(f"{shown}: is a folder; expected a file")
    if kind == "other":   # the rename would replace the device node
        raise OutputError(f"{shown}: is not a regular file (a device, pipe or socket); irring "
                          "writes a new file there, so name one")
    check_replaceable(path, option, writes)
    made: list[Path] = []
    try:
        made = _make_folders(path.absolute().parent)
        tmp = _hidden_sibling(path.absolute(), folder=False)
    except OSError as exc:
        _remove_empty(made)
        blocker = next((p for p in path.absolute().parents if p.exists()), None)
        if blocker is not None and not blocker.is_dir():
            raise OutputError(f"{shown}: {printable(str(blocker))} is a file, so the folder "
                              "cannot be made") from None
        raise OutputError(f"{shown}: cannot write there: {_why(exc)}") from None
    try:
        try:
            yield tmp
        except OSError as exc:
            if isinstance(exc, OutputError) or not (
                    exc.errno in _WRITE_ERRNOS or exc.filename == str(tmp)):
                raise
            raise OutputError(f"{shown}: {_why(exc)}") from exc
        try:
            os.replace(tmp, path)
        except OSError as exc:
            raise OutputError(f"{shown}: cannot move the file in: {_why(exc)}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        _remove_empty(made)
        raise


# folders this process holds (sole_writer, a commit), by (device, inode): a study moving its
# summary into the --out it holds does not wait for itself
_HELD: set[tuple[int, int]] = set()
# how long a commit waits for another process's commit (renames: milliseconds) or study
COMMIT_WAIT_S = 30.0
# how long check_out(held=False) waits, before the work, for a holder to let go: a commit
# is over by then, a study is not
PROBE_WAIT_S = 3.0


@contextlib.contextmanager
def _holding(folder: Path, wait_s: float) -> Iterator[bool]:
    """Hold the advisory lock (flock) on the folder ``folder`` names, waiting up to
    ``wait_s`` for another process to release it; yields False when it stayed held. Where
    the system has no locks, the folder cannot be opened (mode -wx) or this process already
    holds it, yields True at once."""
    deadline = time.monotonic() + wait_s
    while True:
        if fcntl is None:   # pragma: no cover - not POSIX
            yield True
            return
        try:
            fd = os.open(folder, os.O_RDONLY)
        except OSError:   # a folder one may write but not read: held by no one
            yield True
            return
        try:
            st = os.fstat(fd)
            ident = (st.st_dev, st.st_ino)
            if ident in _HELD:
                yield True
                return
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= deadline:
                        yield False
                        return
                    time.sleep(0.02)
                except OSError:   # a file system without locks (NFS without lockd: ENOLCK)
                    yield True
                    return
            try:
                same = os.stat(folder)
            except OSError:
                same = None
            if same is not None and (same.st_dev, same.st_ino) == ident:
                _HELD.add(ident)
                try:
                    yield True
                finally:
                    _HELD.discard(ident)
                return
        finally:
            os.close(fd)   # releases the lock
        # another commit swapped the folder while we waited: hold the one there now


@contextlib.contextmanager
def sole_writer(folder: str | Path, what: str) -> Iterator[None]:
    """Hold ``folder`` (an existing folder) while this process writes ``what`` there;
    :class:`OutputError` at once when another process holds it. Two studies appending to
    one results.csv each rewrote the file the other appended to: one's runs were lost. An
    advisory lock (flock) on the folder itself, so nothing is left behind by a kill; where
    the system has none (Windows), nothing is held. :meth:`OutputSet.commit` takes the same
    lock."""
    with _holding(Path(folder), 0.0) as held:
        if not held:
            raise OutputError(f"{printable(str(folder))}: another irring process is writing "
                              f"{what} there; wait for it to finish, or choose another --out")
        yield


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def write_text_atomic(path: str | Path, text: str, writes: str | None = None) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_file` (``writes``: the kind
    of irring file it is, which may replace one of its kind)."""
    with atomic_file(path, writes=writes) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
