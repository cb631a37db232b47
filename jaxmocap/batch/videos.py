"""The videos of a batch: the inputs a manifest names, each input as the workers find it, and each one's output
folder name (its stem, made distinct)."""

import re
from pathlib import Path
from urllib.parse import urlsplit

from jaxmocap.errors import InputError

RESERVED = frozenset({"batch.json", "batch.csv", ".jaxmocap_batch"})  # what the batch itself keeps in DIR


def read_manifest(path) -> list[str]:
    """The inputs ``path`` names, one per line (files, folders of images, stream URLs); blank lines and lines
    starting with ``#`` skipped."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"--manifest: cannot read {path} ({err})") from None
    return [line.strip() for line in text.splitlines() if line.strip() and not line.strip().startswith("#")]


def is_url(source: str) -> bool:
    """Whether ``source`` names a URL (``scheme://...``) rather than a file."""
    return "://" in source


def resolved(inputs: tuple[str, ...]) -> list[str]:
    """Each input as a worker finds it (a path made absolute: workers start elsewhere), once each, in order."""
    absolute = [source if is_url(source) else str(Path(source).expanduser().resolve()) for source in inputs]
    return list(dict.fromkeys(absolute))


def stem(source: str) -> str:
    """The name ``jaxmocap run`` users would give the input's folder: a file's stem, a folder's name, a URL's last
    path segment (or host), in letters, digits, ``.``, ``_`` and ``-``."""
    if is_url(source):
        parts = urlsplit(source)
        name = Path(parts.path).stem or parts.hostname or "stream"
    else:
        name = Path(source).stem
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "video"
    return name


def folder_names(inputs: list[str]) -> list[str]:
    """Distinct folder names, one per input, in order: the stem, then ``<stem>_2``, ``<stem>_3`` ... for later
    inputs with a stem already taken."""
    taken, names = set(RESERVED), []
    for source in inputs:
        base = stem(source)
        name, n = base, 1
        while name in taken:
            n += 1
            name = f"{base}_{n}"
        taken.add(name)
        names.append(name)
    return names
