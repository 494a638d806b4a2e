"""Files: the one bag finder of the project (each caller picks its rules by parameters) and the one
"read a JSON file or raise naming the path" helper."""

from __future__ import annotations

import glob
import json
import os
from pathlib import Path
from typing import Any, Callable, Iterable


def find_bags(paths: Iterable[str | os.PathLike], *, patterns: bool = False, files_only: bool = False,
              sort_key: Callable | None = None, unique: str = "", empty_dir_error: bool = False,
              empty_error: bool = True, error: type[Exception] = ValueError) -> list[Path]:
    """``.mcap`` bags from files and directories (searched recursively), in the order given.

    A directory contributes its ``*.mcap`` sorted (``sort_key``: None sorts the paths, ``str`` their
    text); a file is taken as it is; a missing path raises ``error`` naming it. ``patterns``: arguments
    holding ``*?[`` are glob patterns (recursive ``**``, hits sorted; none raises). ``files_only``: skip
    directories named ``*.mcap`` inside a searched directory. ``unique``: ``""`` keeps repeats,
    ``"first"`` drops repeats keeping the first, ``"sorted"`` returns the set sorted.
    ``empty_dir_error``: a directory without bags raises; ``empty_error``: no bag at all raises.
    """
    paths = list(paths)
    out: list[Path] = []
    for s in paths:
        hits = [s]
        if patterns and any(ch in str(s) for ch in "*?["):
            hits = sorted(glob.glob(str(s), recursive=True))
            if not hits:
                raise error(f"{s}: no file matches")
        for h in hits:
            p = Path(h)
            if p.is_dir():
                found = sorted((x for x in p.rglob("*.mcap") if not files_only or x.is_file()), key=sort_key)
                if empty_dir_error and not found:
                    raise error(f"{p}: directory holds no .mcap bag")
                out += found
            elif p.is_file():
                out.append(p)
            else:
                raise error(f"{p}: no such bag file or directory")
    if unique == "sorted":
        out = sorted(set(out))
    elif unique == "first":
        seen: set[Path] = set()
        out = [p for p in out if not (p in seen or seen.add(p))]
    elif unique:
        raise ValueError(f"unique={unique!r}: '', 'first' or 'sorted'")
    if empty_error and not out:
        raise error(f"no .mcap bags under {', '.join(map(str, paths))}")
    return out


def read_json(path: str | os.PathLike, what: str, *, max_bytes: int | None = None) -> Any:
    """The JSON content of ``path``; every error starts with the path and says what the file should be:
    FileNotFoundError when it is absent, ValueError when it is larger than ``max_bytes``, not UTF-8 or
    not JSON (other OSErrors, e.g. a directory, pass through)."""
    p = Path(path)
    try:
        if max_bytes is not None and (size := p.stat().st_size) > max_bytes:
            raise ValueError(f"{p}: {size} bytes is larger than the {max_bytes}-byte cap for {what}")
        return json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{p}: {what} not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{p}: {what} is not valid JSON ({e})") from None
