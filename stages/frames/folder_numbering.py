"""What an image folder's names say about the frames' order: a frame number each, or something else.

The frames stage orders a folder's images by the number in each name and names every frame after it
(docs/poses.md): masks and key frames find their frame by that number, and the states are laid along it. Phone
photos are named by a date and a time instead (``20231105_101011.jpg``, ``PXL_20231105_235958100.jpg``), some
with a burst counter after it (``20231105_101011_1.jpg``): the number read is then a time of day (it jumps at
every minute and starts again at midnight) or a counter, and frames ordered by it leave the order they were
taken in. Such folders are refused with the fix, as are names whose number contradicts their order, rather
than trained on a scrambled or stretched time axis.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path

from .errors import FrameSourceError

_DATE_TIME = re.compile(r"(?<!\d)(?:19|20)\d\d(?:0[1-9]|1[0-2])(?:0[1-9]|[12]\d|3[01])[_\-T. ]?\d{6}")
"""A date and a time of day as cameras and phones write them: ``YYYYMMDD_HHMMSS`` (Android, Pixel, DJI)."""

RENAME_FIX = ("rename the images in the order they were taken with a frame number each (IMG_0001.jpg, "
              "IMG_0002.jpg, ...; `ls -v` lists these names in that order), and name masks and key frames by the "
              "new numbers")


def natural_key(path: Path) -> list[tuple[int, int | str]]:
    """``img2.png`` before ``img10.png``: digit runs compared as numbers, the rest as case-folded text."""
    return [(0, int(part)) if part.isdigit() else (1, part.casefold())
            for part in re.split(r"(\d+)", path.name) if part]


def check_numbering(folder: Path, files: list[Path], numbers: list[int]) -> None:
    """Refuse names whose frame number is a date-time, or contradicts the names' own order.

    ``numbers`` are the files' frame numbers (``frame_number_of``), one each and distinct.
    """
    stamped = [p.name for p in files if _DATE_TIME.search(p.stem)]
    if stamped:
        raise FrameSourceError(
            folder, f"{len(stamped)} of the {len(files)} image names carry a date and a time "
                    f"({', '.join(sorted(stamped)[:2])}), not a frame number: the number this stage orders and "
                    "matches frames by would be a time of day (it jumps at every minute and starts again at "
                    "midnight) or a burst counter", RENAME_FIX)
    # names alike but for their digits (take1_0005, take2_0001) must agree with their numbers; names of other
    # forms (IMG_9, DSC-0011) have no order between them to contradict
    forms: dict[str, list[tuple[Path, int]]] = {}
    for path, number in zip(files, numbers, strict=True):
        forms.setdefault(re.sub(r"\d+", "#", path.name.casefold()), []).append((path, number))
    for alike in forms.values():
        by_name = sorted(alike, key=lambda pair: natural_key(pair[0]))
        for (a, na), (b, nb) in itertools.pairwise(by_name):
            if nb < na:
                raise FrameSourceError(
                    folder, f"{b.name} comes after {a.name} by name but carries the smaller frame number ({nb} < {na}; "
                            "the number is the last `_`-separated token of a name, else its last run of digits): the "
                            "names hold more than one number that changes (a take, a date, a counter)", RENAME_FIX)
