"""Progress bars (tqdm) that show on a terminal and stay out of logs and CI."""

from __future__ import annotations

import sys
from typing import Any


def show_progress(progress: Any, name: str = "progress") -> bool:
    """`True`/`False` as given; `None` (auto): only when stderr is a terminal, so that logs,
    CI output and piped runs stay readable."""
    if progress is None:
        stream = sys.stderr
        return bool(getattr(stream, "isatty", lambda: False)())
    if not isinstance(progress, bool):
        raise TypeError(f"{name} must be True, False or None (auto: on a terminal); got {progress!r}")
    return progress


def progress_bar(total: int, desc: str, unit: str, progress: bool | None, *, delay: float = 0.0, **kwargs: Any):
    """A `tqdm` bar shown per `show_progress(progress)`; `delay`: seconds before it appears
    (a run that ends sooner never shows one)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not show_progress(progress), delay=delay, leave=False,
                **kwargs)
