"""The checkpoint file of `learn.fit_stream_operator`: the fit's state after an accepted
Levenberg-Marquardt iteration or a standard error's column, from which a later call (another
process, another day) continues bit for bit as the uninterrupted fit would have (a learned
fit at N = 64 takes hours, most of them in the standard errors' solves).

A file of the standard errors' phase keeps none of the fit's linearisation: `J_theta`, `(J,
L n, p)`, is most of a file's size (`runs/README.md`), and the resumed fit recomputes it at the saved
point, where the fit had computed it before the standard errors, the same function of the same
arrays, so the same bits (a file small enough to carry from one working session to the next;
a fit without standard errors uses only its cost, exact at any point)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from typing import Any

import equinox as eqx
import h5py
import jax
import numpy as np

from integrators.internals import atomic_path, open_hdf5, openblas_kernels

FORMAT = "liepoisson stream operator fit checkpoint"
VERSION = 1
#: The fit's algorithm: raised with any change to what an iteration or a column computes, so
#: that a file written by an older library is refused rather than resumed into other bits.
ALGORITHM = 1
#: The settings of the standard errors alone: a file written with others keeps its iterations,
#: and the resumed fit computes the standard errors afresh.
SE_SETTINGS = ("se_rtol", "se_coarse_degree", "se_start")
#: What a checkpoint's keys (`fingerprint`) are of, in the order `read` names them.
KEYS = ("data", "model", "start")
#: The fit's arrays kept in the file, by name (`_Linearisation`'s fields prefixed `state_`).
STATE = ("cost", "g_theta", "c", "J_theta", "A")


def fingerprint(*trees: Any) -> str:
    """A hash of `trees` (their structure, every leaf's value; a default repr's address left
    out: the same in any process): a checkpoint belongs to the fit whose data, model and start
    give the same."""
    digest = hashlib.sha256()
    for tree in trees:
        digest.update(re.sub(r" at 0x[0-9a-fA-F]+", "", eqx.tree_pformat(tree, short_arrays=True)).encode())
        for leaf in jax.tree_util.tree_leaves(tree):
            if eqx.is_array_like(leaf):
                a = np.ascontiguousarray(np.asarray(leaf))
                digest.update(f"{a.dtype.str}{a.shape}".encode())
                digest.update(a.tobytes())
            else:
                digest.update(repr(leaf).encode())
    return digest.hexdigest()


@dataclasses.dataclass
class FitState:
    """What `fit_stream_operator` carries from one iteration to the next (`phase`
    "iterations"), or into the standard errors (`phase` "standard errors": `columns` of the
    profiled matrix's `p` done, their `B`, `X`, `GX` `(p, J, n)` and `steps` `(p,)`, zero
    past `columns`, and the preconditioner's coarse block `coarse` `(J, k, k)`); `seconds` the fit's wall time so far, over every process that ran it.
    `state` is `None` where it is to be recomputed at `x` (`kept_state`)."""

    phase: str
    x: np.ndarray
    starts: np.ndarray
    lam: float
    nu: float
    forcing: float
    fresh: bool
    done: int
    losses: list[float]
    D_theta: np.ndarray
    state: dict[str, np.ndarray] | None
    stopped: str
    seconds: float
    columns: int = 0
    B: np.ndarray | None = None
    X: np.ndarray | None = None
    GX: np.ndarray | None = None
    steps: np.ndarray | None = None
    coarse: np.ndarray | None = None


def kept_state(phase: str) -> bool:
    """Whether a file of `phase` keeps the fit's linearisation: not in the standard errors'
    phase, where the resumed fit recomputes it (module docstring)."""
    return phase != "standard errors"


def write(path: str | os.PathLike, fit_state: FitState, keys: dict[str, str], settings: dict[str, Any]) -> None:
    """Write `fit_state` to `path` (HDF5; a temporary renamed into place: an interrupted write
    leaves the previous file whole), marked with the fit's `keys` (`KEYS`, each a
    `fingerprint`) and `settings`."""
    s = fit_state
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(format=FORMAT, version=VERSION, keys=json.dumps(keys, sort_keys=True),
                       settings=json.dumps({**settings, "algorithm": ALGORITHM}, sort_keys=True),
                       phase=s.phase, lam=s.lam, nu=s.nu, forcing=s.forcing, fresh=s.fresh, done=s.done,
                       stopped=s.stopped, seconds=s.seconds, columns=s.columns,
                       openblas=json.dumps(openblas_kernels()))  # what the data's bits may depend on (`read`)
        f["x"], f["starts"], f["losses"], f["D_theta"] = s.x, s.starts, np.asarray(s.losses, float), s.D_theta
        if kept_state(s.phase):
            for name in STATE:
                f[f"state_{name}"] = s.state[name]
        if s.B is not None:
            f["B"], f["X"], f["GX"], f["steps"], f["coarse"] = s.B, s.X, s.GX, s.steps, s.coarse


def read(path: str | os.PathLike, keys: dict[str, str], settings: dict[str, Any]) -> FitState:
    """The state in the checkpoint at `path`; `ValueError` naming `path` if it is not such a
    file (or lacks a part), or was written by a fit with other `settings` or by another
    library's algorithm (each differing one named), or of other data, another model or another
    start (`keys` that differ, named)."""
    expected = "a checkpoint of learn.fit_stream_operator"
    where = f"checkpoint {os.fspath(path)!r}"
    with open_hdf5(path, expected) as f:
        attrs = _attrs(f, where, "give another path, or delete the file to start the fit afresh")
        missing = [name for name in ("keys", "settings", "phase", "lam", "nu", "forcing", "fresh", "done", "stopped",
                                     "seconds", "columns") if name not in attrs]
        kept = "phase" in attrs and kept_state(str(attrs["phase"]))
        missing += [name for name in ("x", "starts", "losses", "D_theta", *(f"state_{n}" for n in STATE if kept))
                    if name not in f]
        if missing:
            raise ValueError(f"{where} lacks {', '.join(missing)} (a file cut short or edited): delete it to start the "
                             "fit afresh")
        saved = json.loads(attrs["settings"])
        now = json.loads(json.dumps({**settings, "algorithm": ALGORITHM}, sort_keys=True))
        changed = sorted(k for k in {*saved, *now} if saved.get(k) != now.get(k))
        columns_kept = not changed
        changed = [k for k in changed if k not in SE_SETTINGS]
        if changed:
            what = "; ".join(f"{k}={saved.get(k)!r} then, {now.get(k)!r} now"
                             + (" (from max_step)" if k == "substeps" else "")
                             + (" (the library's fit changed since)" if k == "algorithm" else "") for k in changed)
            raise ValueError(f"{where} was written by a fit with other settings ({what}): resume with the same ones, "
                             "or delete the file to start afresh")
        then = json.loads(attrs["keys"])
        differ = [name for name in KEYS if then.get(name) != keys.get(name)]
        if differ:
            # data made again from the same seeds on another machine can differ at round-off: matrix
            # products round differently in each of OpenBLAS's kernels
            written = json.loads(attrs["openblas"]) if "openblas" in attrs else None  # not kept before
            kernels = openblas_kernels()
            if "data" not in differ:
                hint = ""
            elif written and kernels and written != kernels:
                hint = (f"; it was written where OpenBLAS ran its {', '.join(written)} kernel, this process runs "
                        f"{', '.join(kernels)}, and data made from the same seeds differ at round-off between "
                        f"kernels: resume with the environment's OPENBLAS_CORETYPE={written[0]}")
            else:
                hint = ("; data made again on another machine differ if OpenBLAS's kernel does (numpy.show_runtime() "
                        "names it, the environment's OPENBLAS_CORETYPE sets it)")
            raise ValueError(f"{where} was written by a fit of other {', '.join(differ)} ({', '.join(KEYS)} compared): "
                             f"give another path, or delete the file to start afresh{hint}")
        arrays = {name: np.asarray(f[name]) for name in f}
    has_columns = "B" in arrays and columns_kept
    return FitState(
        phase=str(attrs["phase"]), x=arrays["x"], starts=arrays["starts"], lam=float(attrs["lam"]),
        nu=float(attrs["nu"]), forcing=float(attrs["forcing"]), fresh=bool(attrs["fresh"]), done=int(attrs["done"]),
        losses=[float(v) for v in arrays["losses"]], D_theta=arrays["D_theta"],
        state={name: arrays[f"state_{name}"] for name in STATE} if all(f"state_{n}" in arrays for n in STATE) else None,
        stopped=str(attrs["stopped"]),
        seconds=float(attrs["seconds"]), columns=int(attrs["columns"]) if has_columns else 0,
        B=arrays.get("B") if has_columns else None, X=arrays.get("X") if has_columns else None,
        GX=arrays.get("GX") if has_columns else None, steps=arrays.get("steps") if has_columns else None,
        coarse=arrays.get("coarse") if has_columns else None)


def read_solves(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    r"""`(X, coarse)` of the finished standard errors in the checkpoint at `path`: the solves
    $X \approx G^{-1}B$ `(p, J, n)` and the preconditioner's block `(J, k, k)` (`FitState`),
    to start another fit's (`fit_stream_operator`'s `se_start`); `ValueError` naming `path` if
    it is not such a file or its standard errors are not all done."""
    expected = "a checkpoint of learn.fit_stream_operator"
    where = f"se_start {os.fspath(path)!r}"
    with open_hdf5(path, expected) as f:
        attrs = _attrs(f, where, "give the checkpoint of a fit whose standard errors are done, or None")
        if "X" not in f or "coarse" not in f or int(attrs.get("columns", -1)) != f["X"].shape[0]:
            done = int(attrs.get("columns", 0))
            raise ValueError(f"{where} holds no finished standard errors ({done} columns done"
                             + ("" if "X" not in f else f" of {f['X'].shape[0]}")
                             + "): give the checkpoint of a fit whose standard errors are done, or None")
        return np.asarray(f["X"]), np.asarray(f["coarse"])


def _attrs(f: h5py.File, where: str, fix: str) -> dict[str, Any]:
    """The attributes of `f`, a checkpoint of this format and version (`ValueError` naming
    `where` and saying `fix` if not)."""
    attrs = dict(f.attrs)
    if attrs.get("format") != FORMAT or attrs.get("version") != VERSION:
        raise ValueError(f"{where} is not a checkpoint of learn.fit_stream_operator (format {attrs.get('format')!r}, "
                         f"version {attrs.get('version')!r}; expected {FORMAT!r}, version {VERSION}): {fix}")
    return attrs
