"""Output folders and files that never lose, truncate or mix anything.

The rules (docs/reference/errors.md):

* A command never deletes or overwrites a file it did not create. Writing into a folder that is
  not empty and is not an earlier output of the same command is refused (exit 2) unless
  ``--force``; even with ``--force`` only files of the same name are replaced, nothing else.
* Each output folder carries a manifest, :data:`MANIFEST_NAME`, listing the files the command
  wrote (size and SHA-256 of the content), the command, its arguments and how it ended.
* A new run into its own earlier output folder first deletes the files that folder's manifest
  lists (and only those, and only while their content is still what was written), so an
  earlier run's outputs never mix with a new run's. A manifest is only a claim (anyone can write
  one), so the deletion proves each file itself: the path is walked one folder at a time without
  following a symbolic link (a link anywhere on it and the file is left alone: a planted
  ``sub -> /elsewhere`` cannot reach outside the folder), the file must be a regular file, and its
  size and SHA-256 must match the manifest's (size and time are not proof: both can be copied).
* Every file is written under a temporary name in the same folder and renamed into place, so an
  interrupted or failed run leaves no truncated file. Files written by code that does not use
  these helpers are kept only when the command completes; on failure or Ctrl-C they are removed
  (they may be truncated).
* JSON outputs are valid JSON: NaN and infinities are written as ``null``.

API
---
::

    from vtoladapt.outputs import OutputDir, write_json, save_figure

    target = OutputDir(args.out, command="run", force=args.force)  # checks only: fail fast
    ...validate inputs, run...
    with target as out:                      # claims the folder: manifest, stale outputs removed
        write_json(out.path / "metrics.json", metrics)
        save_figure(fig, out.path / "fig_run.png", dpi=120)
        write_parquet(table, out.path / "runs" / "a.parquet")
        write_text(out.path / "report.md", text)
        with atomic_path(out.path / "x.png") as tmp:   # any writer that takes a path
            some_library_writer(tmp)

The writers work outside a claim too (single-file outputs, e.g. ``tunnel --out DATA.csv``, which
use :func:`check_output_files` and :func:`staged_files` instead of a folder).
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import math
import os
import secrets
import shutil
import stat
import sys
import threading
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Optional

from .config import ConfigError

MANIFEST_NAME = ".vtoladapt-manifest.json"
MANIFEST_FORMAT = "vtoladapt.outputs"
MANIFEST_VERSION = 2
"""2: each file is ``{"bytes": size, "sha256": hex digest}`` (1 recorded size and time only, which
prove nothing: files a version-1 manifest lists are never deleted)."""
PARTIAL_MARK = ".partial-"
"""Temporary files (and staging folders) are named ``.partial-<random><suffix>`` beside their target."""


def _temporary_name(path: Path) -> Path:
    return path.with_name(f"{PARTIAL_MARK}{secrets.token_hex(4)}{path.suffix}")

_JSON_REPAIR_MAX_BYTES = 64 * 2**20

__all__ = ["MANIFEST_NAME", "OutputDir", "OutputError", "add_force_argument", "atomic_path",
           "output_path", "read_manifest",
           "check_output_files",
           "json_safe", "save_figure", "staged_files", "write_bytes", "write_json",
           "write_parquet", "write_text"]


class OutputError(ConfigError):
    """An output path is refused (exists as a file, foreign non-empty folder, ...); exit code 2."""


# --- the claimed folders of this process ---------------------------------------------------------
_ACTIVE: list["OutputDir"] = []
_LOCK = threading.RLock()


def _signature(path: Path) -> Optional[list[int]]:
    """``[size, mtime]`` of a regular file (not through a final link), to see what changed during a run."""
    try:
        st = path.lstat()
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    return [st.st_size, st.st_mtime_ns]


def _owner_of(path: Path) -> Optional["OutputDir"]:
    path = Path(os.path.abspath(path))
    with _LOCK:
        for claim in reversed(_ACTIVE):
            if claim._root == path or claim._root in path.parents:
                return claim
    return None


def _check_path_text(path: Path, flag: str) -> None:
    if str(path) == "" or str(path).strip() == "":
        raise OutputError(f"{flag} {str(path)!r}: empty path; give a folder or file name")
    try:
        name_max = os.pathconf(str(_existing_ancestor(path)), "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        name_max = 255
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            shown = part[:40] + "..." + part[-20:]
            raise OutputError(f"{flag} {shown!r}: a name in the path has {len(part)} characters; "
                              f"allowed: at most {name_max}")
    if "\0" in str(path):
        raise OutputError(f"{flag} {str(path)!r}: contains a NUL character")


def _existing_ancestor(path: Path) -> Path:
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_parents(path: Path, flag: str) -> None:
    """Every existing ancestor of ``path`` must be a folder we may write into."""
    p = Path(os.path.abspath(path)).parent
    while True:
        if p.exists() or p.is_symlink():
            if not p.is_dir():
                raise OutputError(f"{flag} {str(path)!r}: {p} is a file, so it cannot hold a folder")
            if not os.access(p, os.W_OK | os.X_OK) and not Path(os.path.abspath(path)).exists():
                raise OutputError(f"{flag} {str(path)!r}: no permission to write in {p}")
            return
        if p == p.parent:
            return
        p = p.parent


_HASH_BLOCK = 1 << 20


def _open_parent(root: Path, rel: str) -> Optional[tuple[int, str]]:
    """``(folder descriptor, name)`` of ``root / rel``, reached one folder at a time without
    following a symbolic link, or None if a component is a link, not a folder, or missing.
    The caller closes the descriptor."""
    parts = Path(rel).parts
    if not parts or not _safe_relative(rel):
        return None
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(root, flags)
    except OSError:
        return None
    for part in parts[:-1]:
        try:
            nxt = os.open(part, flags | getattr(os, "O_NOFOLLOW", 0), dir_fd=fd)
        except OSError:  # a link (ELOOP/ENOTDIR), a file, or gone
            os.close(fd)
            return None
        os.close(fd)
        fd = nxt
    return fd, parts[-1]


def _content_entry_at(dir_fd: int, name: str) -> Optional[dict]:
    """``{"bytes", "sha256"}`` of the regular file ``name`` in folder ``dir_fd`` (not through a
    link), else None."""
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0), dir_fd=dir_fd)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            return None
        digest = hashlib.sha256()
        while True:
            block = os.read(fd, _HASH_BLOCK)
            if not block:
                break
            digest.update(block)
        return {"bytes": st.st_size, "sha256": digest.hexdigest()}
    except OSError:
        return None
    finally:
        os.close(fd)


def _content_entry(root: Path, rel: str) -> Optional[dict]:
    """The manifest entry of ``root / rel`` as it is now (see :func:`_content_entry_at`)."""
    opened = _open_parent(root, rel)
    if opened is None:
        return None
    fd, name = opened
    try:
        return _content_entry_at(fd, name)
    finally:
        os.close(fd)


def _inspect(root: Path, rel: str, entry: Any) -> str:
    """What ``root / rel`` is against its manifest ``entry``: "missing", "ours" (a regular file,
    reached without a link, whose size and SHA-256 are the entry's), "changed" (a regular file
    with other content), "unproven" (a version-1 entry: size and time only) or "unsafe" (reached
    only through a symbolic link, or not a regular file)."""
    opened = _open_parent(root, rel)
    if opened is None:
        return "unsafe" if os.path.lexists(root / rel) else "missing"
    fd, name = opened
    try:
        try:
            st = os.stat(name, dir_fd=fd, follow_symlinks=False)
        except FileNotFoundError:
            return "missing"
        except OSError:
            return "unsafe"
        if not stat.S_ISREG(st.st_mode):
            return "unsafe"
        if not (isinstance(entry, dict) and isinstance(entry.get("sha256"), str)):
            return "unproven"
        if st.st_size != entry.get("bytes"):
            return "changed"
        now = _content_entry_at(fd, name)
        return "ours" if now is not None and now["sha256"] == entry["sha256"] else "changed"
    finally:
        os.close(fd)


def _remove_if_ours(root: Path, rel: str, entry: dict) -> bool:
    """Delete ``root / rel`` if it is still the file ``entry`` describes (:func:`_inspect`'s "ours"),
    through the folder descriptors the check used, so a link swapped in meanwhile is not followed.
    Then remove the folders it leaves empty, up to ``root``. True if deleted."""
    opened = _open_parent(root, rel)
    if opened is None:
        return False
    fd, name = opened
    try:
        now = _content_entry_at(fd, name)
        if now is None or now != {"bytes": entry.get("bytes"), "sha256": entry.get("sha256")}:
            return False
        os.unlink(name, dir_fd=fd)
    except OSError:
        return False
    finally:
        os.close(fd)
    _remove_empty_folders(root, rel)
    return True


def _unlink_new(root: Path, rel: str) -> None:
    """Delete the regular file ``root / rel`` this run left unfinished (never through a link)."""
    opened = _open_parent(root, rel)
    if opened is None:
        return
    fd, name = opened
    try:
        if stat.S_ISREG(os.stat(name, dir_fd=fd, follow_symlinks=False).st_mode):
            os.unlink(name, dir_fd=fd)
    except OSError:
        pass
    finally:
        os.close(fd)
    _remove_empty_folders(root, rel)


def _remove_empty_folders(root: Path, rel: str) -> None:
    """Remove the folders of ``rel`` that are now empty, innermost first, up to ``root`` (not
    through a link; rmdir removes only an empty folder)."""
    parts = Path(rel).parts[:-1]
    for i in range(len(parts), 0, -1):
        opened = _open_parent(root, "/".join(parts[:i]))
        if opened is None:
            return
        fd, name = opened
        try:
            os.rmdir(name, dir_fd=fd)
        except OSError:
            return
        finally:
            os.close(fd)


def read_manifest(folder: Path) -> Optional[dict]:
    """The manifest of ``folder`` if it holds a valid one, else None."""
    path = Path(folder) / MANIFEST_NAME
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != MANIFEST_FORMAT \
            or not isinstance(doc.get("files"), dict) or not isinstance(doc.get("command"), str):
        return None
    return doc


def _walk_files(root: Path) -> dict[str, list[int]]:
    """Relative path -> signature of every file under ``root`` (not following folder links)."""
    found = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in filenames:
            full = Path(dirpath) / name
            rel = full.relative_to(root).as_posix()
            if rel == MANIFEST_NAME:
                continue
            sig = _signature(full)
            if sig is not None:
                found[rel] = sig
    return found


class OutputDir:
    """A command's output folder: checked on construction, claimed with ``with``.

    Parameters
    ----------
    path : path-like
        The folder (``--out``).
    command : str
        The command writing it (``"run"``, ``"fit"``, ...): a folder holding another command's
        outputs is foreign.
    force : bool
        Write into a foreign non-empty folder anyway (replacing only files of the same name).
    flag : str
        How the user gave the path, for messages.
    planned : iterable of str
        Relative paths the command will write, when it knows them: one that exists and is not an
        earlier output of the command (a user's own ``fig_run.png``) is refused here, before
        anything is touched, rather than when the run reaches it.

    Entering the ``with`` block takes the folder's lock (:mod:`vtoladapt.folder_lock`: a second
    run into it is refused) and checks the folder again under it. The earlier run's outputs are
    deleted and the manifest written only when the first output is (:meth:`claim`), so a command
    that fails before writing anything leaves the folder exactly as it was.

    Raises
    ------
    OutputError
        On construction and again on entry, when the folder is refused.
    """

    def __init__(self, path, command: str, *, force: bool = False, flag: str = "--out",
                 planned: Iterable[str] = ()):
        self.path = Path(path)
        self.command = command
        self.force = force
        self.flag = flag
        self.planned = tuple(planned)
        self._root = Path(os.path.abspath(self.path))
        self._files: dict[str, dict] = {}
        self._before: dict[str, list[int]] = {}
        self._on_entry: dict[str, list[int]] = {}
        self._created: Optional[Path] = None
        self._entered = False
        self._claimed = False
        self._lock = None
        self._stale: list[tuple[str, dict]] = []
        self._was_ours = False
        self.check()

    # --- checks ---------------------------------------------------------------------------------
    def check(self) -> None:
        """Refuse the folder (``OutputError``) unless it is new, empty, ours, or ``force``, and
        not in use by another run."""
        from .folder_lock import LOCK_NAME, holder_if_locked

        path, flag = self.path, self.flag
        _check_path_text(path, flag)
        if path.exists() and not path.is_dir():
            raise OutputError(f"{flag} {str(path)!r}: is a file, not a folder; give a folder name")
        _check_parents(path, flag)
        self._stale = []
        self._was_ours = False
        if not path.is_dir():
            return
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(f"{flag} {str(path)!r}: no permission to write in this folder")
        if self._lock is None:
            holder = holder_if_locked(self._root)
            if holder is not None:
                raise _in_use(flag, path, holder)
        manifest = read_manifest(path)
        present = sorted(e.name for e in os.scandir(path) if e.name not in (MANIFEST_NAME, LOCK_NAME))
        if manifest is None:
            if present and not self.force:
                some = ", ".join(present[:3]) + (", ..." if len(present) > 3 else "")
                raise OutputError(
                    f"{flag} {str(path)!r}: folder is not empty ({some}) "
                    f"and is not an output of 'vtoladapt {self.command}'; choose a new folder, or "
                    "add --force to write into it (files of the same name are replaced)")
            self._check_planned()
            return
        if manifest["command"] != self.command:
            if not self.force:
                raise OutputError(
                    f"{flag} {str(path)!r}: holds the outputs of 'vtoladapt {manifest['command']}'; "
                    f"'vtoladapt {self.command}' would mix with or replace them; choose a new "
                    "folder, or add --force")
            self._check_planned()
            return
        self._was_ours = True
        for rel, entry in manifest["files"].items():
            if not _safe_relative(rel):
                continue
            state = _inspect(self._root, rel, entry)
            if state == "ours":
                self._stale.append((rel, entry))
            elif state != "missing" and not self.force:
                why = {"changed": f"was changed after vtoladapt {self.command} wrote it",
                       "unproven": "is listed by a manifest of an earlier vtoladapt that recorded no content hash, "
                                   "so it cannot be proven to be that run's output",
                       "unsafe": "is reached through a symbolic link or is not a regular file, and vtoladapt "
                                 "never deletes through a link"}[state]
                raise OutputError(
                    f"{flag} {str(path)!r}: {rel} {why}; move it away, or add --force (it is then kept, "
                    "or replaced if the new run writes a file of that name)")
        self._check_planned()

    def _check_planned(self) -> None:
        """Refuse a planned output whose name is taken by a file that is not an earlier output
        (unless ``force``), or that would be written through a symbolic link (always)."""
        ours = {rel for rel, _ in self._stale}
        for rel in self.planned:
            inner = self._root
            for part in Path(rel).parts:
                inner = inner / part
                if inner.is_symlink():
                    raise OutputError(f"{self.flag} {str(self.path)!r}: {rel}: {inner} is a symbolic link; "
                                      "vtoladapt writes its outputs only into the folder itself; remove the "
                                      "link or choose another folder")
            if rel not in ours and os.path.lexists(self._root / rel) and not self.force:
                raise OutputError(f"{self.flag} {str(self.path)!r}: {rel} exists and is not an output of "
                                  f"'vtoladapt {self.command}', and this run writes a file of that name; move "
                                  "it away, or add --force to replace it")

    # --- claim ------------------------------------------------------------------------------------
    def __enter__(self) -> "OutputDir":
        from .folder_lock import FolderInUse, acquire

        if self._entered:
            raise RuntimeError("an OutputDir is claimed once")
        self.check()  # again: the folder may have changed while the inputs were validated
        created = None
        if not self._root.exists():
            created = self._root
            while not created.parent.exists():
                created = created.parent
            self._root.mkdir(parents=True, exist_ok=True)
        try:
            try:
                self._lock = acquire(self._root, self.command)
            except FolderInUse as exc:
                raise _in_use(self.flag, self.path, exc.holder) from None
            self.check()  # under the lock: no other run changes the folder from here on
        except BaseException:
            if self._lock is not None:
                self._lock.release()
                self._lock = None
            if created is not None:
                _remove_empty_tree(created)
            raise
        self._entered = True
        self._created = created
        stale = {rel for rel, _ in self._stale}  # the earlier run's, deleted at the claim: not foreign
        self._on_entry = _walk_files(self._root)  # every file's signature, the earlier run's included
        self._before = {rel: sig for rel, sig in self._on_entry.items() if rel not in stale}
        with _LOCK:
            _ACTIVE.append(self)
        return self

    def claim(self, written=frozenset()) -> None:
        """Delete the earlier run's outputs and write the manifest ("running"): done by the first
        output written through this module (or at a successful end), not on entry, so that a
        command failing before it writes anything changes nothing on disk. ``written``: files this
        run wrote itself (at a successful end), kept even where they are byte for byte the earlier
        run's (a figure drawn again from the same seed)."""
        with _LOCK:
            if self._claimed:
                return
            self._claimed = True
            for rel, entry in self._stale:  # an earlier run of this command: its outputs go first
                if rel not in written:
                    _remove_if_ours(self._root, rel, entry)
            self._write_manifest("running")

    def record(self, path) -> None:
        """Note ``path`` (inside the folder) as a complete output of this run."""
        self.claim()
        full = Path(os.path.abspath(path))
        rel = full.relative_to(self._root).as_posix()
        entry = _content_entry(self._root, rel)
        if entry is not None:
            with _LOCK:
                self._files[rel] = entry
            self._write_manifest("running")

    def is_foreign(self, path) -> bool:
        """True for a file that was in the folder before this run and is not one of its outputs."""
        full = Path(os.path.abspath(path))
        try:
            rel = full.relative_to(self._root).as_posix()
        except ValueError:
            return False
        return rel in self._before and rel not in self._files

    def __exit__(self, exc_type, exc, tb) -> bool:
        from .folder_lock import LOCK_NAME

        with _LOCK:
            if self in _ACTIVE:
                _ACTIVE.remove(self)
        try:
            now = _walk_files(self._root)
            now.pop(LOCK_NAME, None)
            new = {rel: sig for rel, sig in now.items() if self._before.get(rel) != sig}
            for rel in list(new):
                if Path(rel).name.startswith(PARTIAL_MARK):  # a writer's temporary file: never an output
                    _unlink_new(self._root, rel)
                    new.pop(rel)
            if exc_type is None:
                self.claim(written=frozenset(rel for rel, sig in now.items() if self._on_entry.get(rel) != sig))
                for rel in new:
                    if rel.endswith(".json"):
                        _repair_json(self._root / rel)
                self._files.update(_entries(self._root, (rel for rel in new if rel not in self._files)))
                self._write_manifest("complete")
                return False
            # failed or interrupted: keep the files written completely (through this module); remove
            # the rest, which may be truncated, unless they overwrote a file that was here before
            for rel in new:
                if rel not in self._files and rel not in self._before:
                    _unlink_new(self._root, rel)
            self._files = {rel: e for rel, e in self._files.items() if (self._root / rel).exists()}
            from .errors import Terminated

            status = ("terminated" if issubclass(exc_type, Terminated) else
                      "interrupted" if issubclass(exc_type, KeyboardInterrupt) else "failed")
            if self._claimed:
                self._write_manifest(status)
            elif self._created is not None:  # nothing of this run was written: leave the disk as it was
                self._lock.release()
                _remove_empty_tree(self._created)
            return False
        finally:
            if self._lock is not None:
                self._lock.release()

    @property
    def files(self) -> list[str]:
        """Relative paths of the outputs recorded so far."""
        return sorted(self._files)

    def _write_manifest(self, status: str) -> None:
        from ._version import __version__ as version

        doc = {"format": MANIFEST_FORMAT, "version": MANIFEST_VERSION, "command": self.command,
               "status": status, "argv": list(sys.argv[1:]), "vtoladapt": version,
               "updated": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "files": dict(sorted(self._files.items()))}
        _atomic_write_bytes(self._root / MANIFEST_NAME,
                            (json.dumps(doc, indent=1) + "\n").encode(), register=False)


def _in_use(flag: str, path: Path, holder: str) -> OutputError:
    return OutputError(f"{flag} {str(path)!r}: in use by another vtoladapt run ({holder}); wait for it to end, "
                       "or choose another folder")


def _entries(root: Path, rels: Iterable[str]) -> dict[str, dict]:
    """Manifest entries (:func:`_content_entry`) of the regular files ``rels`` under ``root``."""
    out = {}
    for rel in rels:
        entry = _content_entry(root, rel)
        if entry is not None:
            out[rel] = entry
    return out


def _safe_relative(rel: str) -> bool:
    p = Path(rel)
    return not p.is_absolute() and ".." not in p.parts


def _remove_empty_tree(top: Path) -> None:
    """Remove ``top`` and the folders under it if they hold no file (never a file)."""
    for dirpath, dirnames, filenames in os.walk(top, topdown=False):
        if not filenames:
            with contextlib.suppress(OSError):
                os.rmdir(dirpath)


def _repair_json(path: Path) -> None:
    """Rewrite a JSON output holding bare NaN/Infinity (not JSON) with ``null`` instead."""
    try:
        if path.stat().st_size > _JSON_REPAIR_MAX_BYTES:
            return
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return
    if "NaN" not in text and "Infinity" not in text:
        return
    try:
        json.loads(text, parse_constant=_reject)
        return
    except ValueError:
        pass
    try:
        doc = json.loads(text)
    except ValueError:
        return
    _atomic_write_bytes(path, (json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n").encode(),
                        register=False)


def _reject(name: str):
    raise ValueError(name)


# --- single-file outputs ---------------------------------------------------------------------------
def check_output_files(paths: Iterable, command: str, *, is_ours: Callable[[Path], bool],
                       force: bool = False, flag: str = "--out") -> None:
    """Refuse to replace existing files that ``is_ours`` does not recognise (unless ``force``).

    For commands whose output is one file (and its side files) rather than a folder.
    """
    for p in paths:
        p = Path(p)
        _check_path_text(p, flag)
        if p.is_dir():
            raise OutputError(f"{flag} {str(p)!r}: is a folder; give a file name")
        _check_parents(p, flag)
        if p.exists() and not force and not is_ours(p):
            raise OutputError(f"{flag}: {p} exists and is not an output of 'vtoladapt {command}'; "
                              "choose another name, or add --force to replace it")


@contextlib.contextmanager
def staged_files(folder) -> Iterator[Path]:
    """A temporary folder inside ``folder``; on success each file in it is renamed into ``folder``.

    For writers that make several files whose names refer to each other (a CSV and its side
    file). On an exception the staging folder is removed and ``folder`` is untouched.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stage = folder / f"{PARTIAL_MARK}{secrets.token_hex(4)}"
    stage.mkdir()
    try:
        yield stage
        for f in sorted(stage.iterdir()):
            os.replace(f, folder / f.name)
            _register(folder / f.name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


# --- atomic writers -----------------------------------------------------------------------------------
def _register(path: Path) -> None:
    owner = _owner_of(path)
    if owner is not None:
        owner.record(path)


def remove_output(path) -> None:
    """Remove an output this run wrote and drop it from its folder's manifest (a log that was
    needed only while the run was analysed: ``[output] log = false``)."""
    path = Path(path)
    owner = _owner_of(path)
    if owner is not None and not owner.force and owner.is_foreign(path):
        raise OutputError(f"{path}: exists and was not written by 'vtoladapt {owner.command}'; not removed")
    path.unlink()
    if owner is not None:
        rel = Path(os.path.abspath(path)).relative_to(owner._root).as_posix()
        with _LOCK:
            owner._files.pop(rel, None)
        owner._write_manifest("running")


def _refuse_foreign(path: Path) -> None:
    owner = _owner_of(path)
    if owner is None:
        return
    # outputs go into real folders of the claimed one: a planted link (runs -> /elsewhere) would
    # put them, and their replacement of a file of the same name, outside it
    inner = owner._root
    for part in Path(os.path.abspath(path)).relative_to(owner._root).parts:
        inner = inner / part
        if inner.is_symlink():
            raise OutputError(f"{path}: {inner} is a symbolic link; vtoladapt writes its outputs only into "
                              f"the folders of {owner.flag} themselves; remove the link or choose another folder")
    if not owner.force and owner.is_foreign(path):
        raise OutputError(f"{path}: exists and was not written by 'vtoladapt {owner.command}'; "
                          "move it away, or add --force to replace it")
    owner.claim()  # the first output: the earlier run's go now (one of them may have this name)


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """Yield a temporary path (same folder, same suffix) to write; renamed to ``path`` on success.

    On an exception (including Ctrl-C) the temporary file is removed and ``path`` is untouched.
    Inside a claimed :class:`OutputDir` the file is recorded in its manifest.
    """
    path = Path(path)
    _refuse_foreign(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _register(path)


def _atomic_write_bytes(path: Path, data: bytes, register: bool = True) -> Path:
    if register:
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary_name(path)
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return _atomic_write_bytes(Path(path), data)


def write_text(path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return _atomic_write_bytes(Path(path), text.encode("utf-8"))


def json_safe(obj: Any) -> Any:
    """``obj`` with NaN and infinities as None, numpy scalars and arrays as Python, paths as text."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    if isinstance(obj, Path):
        return str(obj)
    tolist = getattr(obj, "tolist", None)  # numpy arrays and scalars
    if tolist is not None:
        return json_safe(tolist())
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")


def write_json(path, obj: Any, indent: int = 2) -> Path:
    """Write ``obj`` as JSON atomically; NaN and infinities become ``null`` (valid JSON)."""
    text = json.dumps(json_safe(obj), indent=indent, allow_nan=False) + "\n"
    return write_text(path, text)


def write_parquet(table, path) -> Path:
    """Write a ``pyarrow.Table`` to ``path`` atomically."""
    import pyarrow.parquet as pq

    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return Path(path)


def save_figure(fig, path, **savefig_kwargs) -> Path:
    """``fig.savefig(path, ...)`` atomically (the format follows the suffix, as in matplotlib)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **savefig_kwargs)
    return Path(path)


def add_force_argument(parser) -> None:
    """Add the shared ``--force`` flag to a command's ``argparse`` parser."""
    parser.add_argument("--force", action="store_true",
                        help="write into a non-empty folder (or over a file) that is not an "
                             "earlier output of this command; only files of the same name are "
                             "replaced")


def output_path(text: str) -> Path:
    """``argparse`` type of ``--out``: a path, refusing the empty string (it would mean '.')."""
    import argparse

    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: empty path; give a folder or file name")
    return Path(text)
