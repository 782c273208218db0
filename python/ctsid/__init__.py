"""ctsid: continuous-time sparse identification of machines from short, noisy records.

From a few short runs of measured inputs ``u`` and outputs ``y`` sampled every ``tau`` seconds,
ctsid finds models ``y^(n) = P(y, y', ..., y^(n-1), u)``: sparse polynomials plus named terms
(``sign(y_d1)`` for Coulomb friction, ``abs(y_d1)*y_d1`` for drag, ...) that simulate from the
inputs alone. It implements M. Alamir, "On continuous-time sparse identification of nonlinear
polynomial systems", in Rust; this package is a thin layer over the same library the ``ctsid``
command line uses, and reads and writes the same model files.

Quick start::

    import pandas as pd, ctsid
    ctsid.throttle_dataset("throttle.csv", runs=40)   # the paper's experiment: run, t, u, y
    data = pd.read_csv("throttle.csv")
    model = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=0.003, run_column="run",
                           train="0-24", validation="25-29", test="30-39", degree=3)
    model.print()                               # y_d3 = ...
    sims = model.simulate(data, tau=0.003, run_column="run")   # {run id: array (samples, outputs)}
    model.save("throttle.json")                 # `ctsid simulate throttle.json ...` reads it

Data are a pandas DataFrame (one run, or several told apart by ``run_column``), a list of
DataFrames (one per run), a dict ``{run id: DataFrame}``, or the same with 2-D numpy arrays
(samples x columns) and ``columns=[...]`` naming their columns. A frame with a ``run`` column of
several values needs ``run_column`` (it is refused without: its runs would be joined). One long
record is cut into runs by ``segment=SECONDS`` (as the command line's ``--segment``: pieces
``0``, ``1``, ... of one run, ``RUN#0``, ``RUN#1``, ... of run ``RUN``, a remainder under half a
piece joined to the last, and a run list naming ``RUN`` takes all its pieces). The times are
not read: ``tau`` is the sampling period. Errors in the data or settings raise
:class:`CtsidError` (a ``ValueError``) with the one-line message the command line prints. Long calls release the GIL; progress goes to the ``logging`` logger ``"ctsid"`` at INFO.
"""

from __future__ import annotations

import json
import math
import numbers
import os
import warnings
from collections.abc import Iterable
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _ctsid
from ._ctsid import CtsidError

__all__ = [
    "CtsidError",
    "Model",
    "Discovery",
    "identify",
    "simulate",
    "derive",
    "discover",
    "load",
    "throttle_dataset",
]

RunList = Union[str, Sequence[Any], None]


# Integers beyond this cannot cross into the extension (an unsigned 64-bit word): 2**70 raised
# Python's own "OverflowError: int too big to convert", naming no setting.
_INT_MAX = 2**64 - 1


def _int(name: str, v: Any, low: int = 0) -> int:
    """An integer setting: Python or numpy integers only (``2.7`` was cut to 2 without a word)."""
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise TypeError(f"{name}: give an integer, not {v!r}")
    if v < low:
        raise ValueError(f"{name}: {v} is below {low}")
    if v > _INT_MAX:
        raise ValueError(f"{name}: {v} is beyond the largest integer ctsid takes ({_INT_MAX})")
    return int(v)


def _unmasked(name: str, a: Any) -> Any:
    """Refuses a numpy masked array with masked samples: ``np.asarray`` drops the mask and
    hands on the values under it (a masked stretch of zeros was fitted as data)."""
    if isinstance(a, np.ma.MaskedArray) and np.ma.is_masked(a):
        raise CtsidError(
            f"{name}: a masked array with {int(np.ma.count_masked(a))} masked (missing) samples; "
            "fill or cut them first"
        )
    return a


def _real(name: str, v: Any) -> float:
    """A real setting: numbers only (a string ``"0.003"`` was read as one)."""
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name}: give a number, not {v!r}")
    return float(v)


def _flag(name: str, v: Any) -> bool:
    """A yes/no setting: ``bool("no")`` is True, so strings are refused."""
    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"{name}: give True or False, not {v!r}")
    return bool(v)


def _path(name: str, p: Any) -> str:
    """A file name: ``str`` or a path object (``None`` was written to a file named None)."""
    if isinstance(p, (str, os.PathLike)):
        q = os.fspath(p)
        if isinstance(q, str):
            return q
    raise TypeError(f"{name}: give a file name (str or pathlib.Path), not {p!r}")


def _names(name: str, v: Any) -> List[str]:
    """A list of names: one string is refused (it was split into characters), as is None."""
    if isinstance(v, str):
        raise TypeError(f"{name}: give a list of names, e.g. [{v!r}]")
    if v is None or not isinstance(v, Iterable):
        raise TypeError(f"{name}: give a list of names, not {v!r}")
    return [str(x) for x in v]


def _unique(names: Sequence[Any], where: str) -> None:
    seen: Dict[str, int] = {}
    for c in names:
        k = str(c)
        if k in seen:
            raise CtsidError(f"{where}: column '{k}' is named twice")
        seen[k] = 1


def _finite_or_none(x: float) -> Optional[float]:
    """A figure the command line prints as ``-`` (a constant measured output) is ``None``."""
    return x if math.isfinite(x) else None


def _frames(data: Any, run_column: Optional[str], columns: Optional[Sequence[str]]):
    """(run id, table) pairs, each table a mapping column name -> 1-D float array."""
    if isinstance(data, (Mapping, list, tuple)) and not _is_frame(data) and run_column is not None:
        raise ValueError(
            "run_column: a list or dict of runs already gives one run per item; "
            "run_column splits a single DataFrame"
        )
    if isinstance(data, Mapping) and not _is_frame(data):
        return [(str(k), _table(v, columns)) for k, v in data.items()]
    if isinstance(data, (list, tuple)):
        if len(data) and all(_is_frame(d) or isinstance(d, np.ndarray) for d in data):
            return [(str(i), _table(d, columns)) for i, d in enumerate(data)]
        raise ValueError(
            "data: a list must hold one DataFrame or 2-D array per run; "
            "for one run give the DataFrame or array itself"
        )
    table = _table(data, columns)
    if run_column is None:
        # A frame with a run-id column given as one run joins its runs end to end, and every
        # figure still looks plausible (the throttle frame of 30 runs scored 85.9 %).
        for name in table:
            if str(name).strip().lower() in ("run", "run_id"):
                n = len(set(np.asarray(table[name]).tolist()))
                if n > 1:
                    raise CtsidError(
                        f"the data have a column '{name}' with {n} different values but no "
                        f"run_column: the runs would be joined end to end; give "
                        f"run_column='{name}' (or drop the column if the data are one run)"
                    )
        return [("0", table)]
    if run_column not in table:
        raise CtsidError(f"run column '{run_column}' not found (columns: {', '.join(table)})")
    ids = [_cell_run_id(v, run_column, i) for i, v in enumerate(np.asarray(table[run_column]).tolist())]
    rows: Dict[str, List[int]] = {}
    for i, key in enumerate(ids):
        rows.setdefault(key, []).append(i)
    return [
        (key, {c: np.asarray(v)[idx] for c, v in table.items() if c != run_column})
        for key, idx in rows.items()
    ]


def _cell_run_id(v: Any, column: str, row: int) -> str:
    # A missing id is a lost cell, not a run: grouping the rows of NaN, None, pandas' NA or NaT
    # would join pieces of different experiments into one run (the command line refuses an
    # empty id too). A string id "nan" is a name like any other.
    missing = v is None or type(v).__name__ in ("NAType", "NaTType")
    missing = missing or (isinstance(v, (float, np.floating)) and np.isnan(v))
    if missing or (isinstance(v, str) and not v.strip()):
        raise CtsidError(f"run column '{column}' row {row}: no run id (a lost cell, not a run)")
    return _run_id(v)


def _run_id(v: Any) -> str:
    if isinstance(v, (float, np.floating)) and float(v).is_integer():
        return str(int(v))
    return str(v)


def _is_frame(d: Any) -> bool:
    return hasattr(d, "columns") and hasattr(d, "to_numpy")


def _table(d: Any, columns: Optional[Sequence[str]]) -> Dict[str, np.ndarray]:
    """A DataFrame or 2-D array as column name -> 1-D array."""
    if _is_frame(d):
        if columns is not None:
            raise ValueError("columns: names the columns of a numpy array; a DataFrame has its own")
        _unique(d.columns, "data")
        return {str(c): d[c].to_numpy() for c in d.columns}
    a = np.asarray(_unmasked("data", d))
    if a.ndim != 2:
        raise ValueError(
            f"data: a {a.ndim}-D array; give a 2-D array (samples x columns) with "
            "columns=[...] naming its columns, or a DataFrame"
        )
    if columns is None:
        raise ValueError("data: a numpy array needs columns=[...] naming its columns")
    if len(columns) != a.shape[1]:
        raise ValueError(
            f"data: {a.shape[1]} columns in the array but {len(columns)} names in columns=[...]"
        )
    _unique(columns, "columns")
    return {str(c): a[:, k] for k, c in enumerate(columns)}


def _time_like(name: str) -> bool:
    """``t``, ``time``, ``t_s``, ``time [s]``, ... (not ``temp``)."""
    n = str(name).strip().lower()
    return any(n == t or (n.startswith(t) and n[len(t)] in "_ [(") for t in ("t", "time"))


def _check_time(rid: str, table: Mapping[str, Any], names: Sequence[str], tau: float) -> None:
    """A column named like time whose uniform step is not ``tau`` means the data are sampled
    otherwise (the times are not read): every derivative and free run would use the wrong step
    (``tau=0.03`` on 3 ms data scored a fit of -264 % without a word). A step of ``tau`` in ms,
    us, min or h is that sampling in another unit; a column that is not uniform is not time."""
    for name, v in table.items():
        if name in names or not _time_like(name):
            continue
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            continue
        if a.size < 3 or not np.all(np.isfinite(a)):
            continue
        d = np.diff(a)
        step = float(np.median(d))
        if step <= 0 or float(np.max(np.abs(d - step))) > 1e-3 * step:
            continue
        ratio = step / tau
        if any(abs(ratio / k - 1) < 0.01 for k in (1.0, 1e3, 1e6, 1 / 60, 1 / 3600)):
            continue
        raise CtsidError(
            f"run {rid}: column '{name}' steps by {step:g} s but tau is {tau:g} s; give the "
            f"data's sampling period as tau (the times themselves are not read)"
        )


def _records(
    data: Any,
    names: Sequence[str],
    run_column: Optional[str],
    columns: Optional[Sequence[str]],
    tau: Optional[float] = None,
):
    """The (names, runs) the extension takes: the named channels of every run as float lists;
    with ``tau``, a column named like time is checked against it (:func:`_check_time`)."""
    if run_column is not None and str(run_column) in names:
        # It was looked up in each run after the split and named by a sample value.
        raise CtsidError(
            f"column '{run_column}' is the run column; it cannot also be an input or output channel"
        )
    runs = []
    for rid, table in _frames(data, run_column, columns):
        missing = [n for n in names if n not in table]
        if missing:
            raise CtsidError(
                f"column '{missing[0]}' not found in run {rid} (columns: {', '.join(table)})"
            )
        if all(len(np.asarray(table[n])) == 0 for n in names):
            # An empty frame was reported as a constant output.
            raise CtsidError(f"run {rid}: no data rows")
        if tau is not None:
            _check_time(rid, table, names, tau)
        cols = []
        for n in names:
            v = np.asarray(table[n])
            if v.dtype.kind not in "biuf":
                raise CtsidError(f"run {rid}, column '{n}': values are not numbers ({v.dtype})")
            cols.append(v.astype(float).tolist())
        runs.append((rid, cols))
    return list(names), runs


def _segment(v: Any) -> Optional[float]:
    """A piece's length in seconds (the library checks it against ``tau``)."""
    return None if v is None else _real("segment", v)


def _run_list(v: RunList) -> Optional[str]:
    if v is None:
        return None
    if isinstance(v, str):
        return v
    return ",".join(_run_id(x) for x in v)


def _tau(tau: Optional[float], model: Optional["Model"] = None) -> float:
    if tau is not None:
        return _real("tau", tau)
    if model is not None and model.tau is not None:
        return model.tau
    raise ValueError("tau: give the sampling period in seconds")


class Model:
    """An identified (or hand-written) model: equations per output, simulation, the model file.

    ``str(model)`` and :meth:`print` show the equations; :meth:`save` writes the same
    ``ctsid-model/2`` file as the command line, :func:`load` reads one.
    """

    def __init__(self, inner: "_ctsid.Model", summary: Optional[dict] = None):
        if not isinstance(inner, _ctsid.Model):
            raise TypeError("Model: read a model file with ctsid.load(path), or identify one")
        self._m = inner
        #: What the identification reported (orders, test NRMSE per output, engine,
        #: refinement), for a model from :func:`identify`; else ``None``.
        self.summary = summary

    @staticmethod
    def load(path: str) -> "Model":
        """Reads a model file."""
        return Model(_ctsid.Model.load(_path("path", path)))

    @staticmethod
    def from_json(text: str) -> "Model":
        """The model of a JSON text (``ctsid-model/2``), checked strictly."""
        return Model(_ctsid.Model.from_json(text))

    def to_json(self) -> str:
        return self._m.to_json()

    def save(self, path: str) -> None:
        """Writes the model file (whole or not at all)."""
        self._m.save(_path("path", path))

    def equations(self) -> List[str]:
        """One equation per output, ``y_d2 = ...``."""
        return self._m.equations()

    def print(self) -> None:
        print(str(self))

    def coefficients(self) -> List[dict]:
        """Every term: output, term, coefficient, standard error (``None`` where not estimated)."""
        return [
            {"output": o, "term": t, "coefficient": c, "std_error": s}
            for o, t, c, s in self._m.coefficients()
        ]

    @property
    def outputs(self) -> List[str]:
        return self._m.outputs

    @property
    def inputs(self) -> List[str]:
        return self._m.inputs

    @property
    def orders(self) -> List[int]:
        return self._m.orders

    @property
    def tau(self) -> Optional[float]:
        return self._m.tau

    def _run(self, data, tau, run_column, columns, segment):
        tau = _tau(tau, self)
        names, runs = _records(data, self.outputs + self.inputs, run_column, columns, tau)
        return self._m.simulate(tau, names, runs, segment=_segment(segment))

    def simulate(
        self,
        data: Any,
        tau: Optional[float] = None,
        run_column: Optional[str] = None,
        columns: Optional[Sequence[str]] = None,
        segment: Optional[float] = None,
    ) -> Union[np.ndarray, Dict[str, np.ndarray]]:
        """Free runs from the measured inputs, each from the initial state fitted on the run's
        first 200 samples (the convention of every score ctsid prints).

        Returns an array (samples x outputs) for one run, else ``{run id: array}``. ``tau``
        defaults to the model's own; ``segment`` cuts the runs into pieces of that many seconds.
        """
        sims = self._run(data, tau, run_column, columns, segment)
        out = {rid: np.asarray(sim).T for rid, sim, _, _ in sims}
        return next(iter(out.values())) if len(out) == 1 else out

    def score(
        self,
        data: Any,
        tau: Optional[float] = None,
        run_column: Optional[str] = None,
        columns: Optional[Sequence[str]] = None,
        segment: Optional[float] = None,
    ) -> List[dict]:
        """Per run and output: RMS, NRMSE (RMS over the measured output's standard deviation)
        and fit in percent, ``100 (1 - NRMSE)``, as ``ctsid simulate`` prints them; ``None``
        where the command line prints ``-`` (the measured output is constant in that run)."""
        rows = []
        for rid, _, rms, nrmse in self._run(data, tau, run_column, columns, segment):
            for o, r, e in zip(self.outputs, rms, nrmse):
                e = _finite_or_none(e)
                fit = None if e is None else 100.0 * (1.0 - e)
                rows.append({"run": rid, "output": o, "rms": r, "nrmse": e, "fit_percent": fit})
        return rows

    def __reduce__(self):
        # Pickled as its model file's text (exact: floats are written in shortest round-trip
        # form), so a model crosses to multiprocessing workers and caches; without this pickle
        # raised "cannot pickle ... object".
        return (_model_from_json, (self.to_json(), self.summary))

    def __str__(self) -> str:
        return str(self._m)

    def __repr__(self) -> str:
        return repr(self._m)


def _model_from_json(text: str, summary: Optional[dict]) -> Model:
    """What unpickling a :class:`Model` calls."""
    return Model(_ctsid.Model.from_json(text), summary)


def identify(
    data: Any,
    outputs: Sequence[str],
    inputs: Sequence[str] = (),
    tau: Optional[float] = None,
    run_column: Optional[str] = None,
    columns: Optional[Sequence[str]] = None,
    train: RunList = None,
    validation: RunList = None,
    test: RunList = None,
    degree: int = 3,
    order: Union[int, Sequence[int], None] = None,
    orders: Optional[Sequence[int]] = None,
    terms: Sequence[str] = (),
    engine: str = "auto",
    refine: bool = True,
    segment: Optional[float] = None,
    limits: bool = True,
) -> Model:
    """Identifies a model, with the command line's defaults (``ctsid identify``).

    Runs are named by lists as the command line takes them (``"0-3"``, ``"a,b"``) or as Python
    lists of run ids; training defaults to every run not named for validation or test.
    ``order`` fixes the order (an int for every output, or one per output); otherwise each
    output's order is searched over ``orders`` (default 1 to 4) by the eta-rule. ``terms`` adds
    named terms to the dictionary (``"sign(y_d1)"``). ``engine`` is ``"auto"``, ``"cpu"`` or
    ``"gpu"``. ``segment`` cuts long runs into pieces of that many seconds, each a run (named
    as the module's docstring says). ``limits=False`` leaves out the hard limit read from an
    output the training runs hold at its extreme value (an overflow, an end stop; a warning says
    when one is read). The returned model's ``summary`` holds the orders and test
    NRMSE; its model file (:meth:`Model.save`, :meth:`Model.to_json`) has the ``training``
    section ``ctsid identify -o`` writes, with the fit's timings.
    """
    tau = _tau(tau)
    outputs, inputs = _names("outputs", outputs), _names("inputs", inputs)
    if order is not None and orders is not None:
        raise ValueError("order fixes the orders and orders lists those to search; give one of them")
    names, runs = _records(data, outputs + inputs, run_column, columns, tau)
    if isinstance(order, numbers.Integral) and not isinstance(order, bool):
        order = [order] * len(outputs)
    inner, summary = _ctsid.identify(
        tau,
        names,
        runs,
        outputs,
        inputs,
        _int("degree", degree, 1),
        train=_run_list(train),
        validation=_run_list(validation),
        test=_run_list(test),
        order=None if order is None else [_int("order", o, 1) for o in order],
        orders=None if orders is None else [_int("orders", o, 1) for o in orders],
        terms=_names("terms", terms),
        engine=str(engine),
        refine=_flag("refine", refine),
        segment=_segment(segment),
        limits=_flag("limits", limits),
    )
    summary = json.loads(summary)
    # What the command line notes on standard error (a named term no chosen order could use).
    for note in summary.get("notes", []):
        warnings.warn(f"ctsid: {note}", stacklevel=2)
    return Model(inner, summary)


def simulate(model: Model, data: Any, **kwargs: Any):
    """``model.simulate(data, ...)``."""
    return model.simulate(data, **kwargs)


def load(path: str) -> Model:
    """Reads a model file written by ctsid (Python or command line)."""
    return Model.load(path)


def derive(y: Any, tau: float, order: int) -> Tuple[np.ndarray, np.ndarray]:
    """Derivatives y, y', ..., y^(order) of one uniformly sampled signal by the self-tuning
    smoother: ``(values, sigmas)``, each an array (order + 1) x samples; row 0 is the smoothed
    signal, ``sigmas`` the per-sample standard deviations."""
    raw = np.asarray(_unmasked("y", y))
    if raw.dtype.kind not in "biuf":
        raise CtsidError(f"y: values are not numbers ({raw.dtype})")
    a = raw.astype(float)
    if a.ndim != 1:
        raise ValueError(f"y: a {a.ndim}-D array; give one signal as a 1-D array")
    values, sigmas = _ctsid.derive(a.tolist(), _real("tau", tau), _int("order", order))
    return np.asarray(values), np.asarray(sigmas)


class Discovery:
    """What :func:`discover` found: ``verdict`` ("added", "nothing", ...), ``text`` (the
    evidence and the before/after table, as the command line prints it), ``model`` (the
    augmented model), ``nrmse_before`` / ``nrmse_after`` on the test runs (``None`` where the
    measured output is constant)."""

    def __init__(self, verdict: str, text: str, model: Model, before: float, after: float):
        self.verdict, self.text, self.model = verdict, text, model
        self.nrmse_before, self.nrmse_after = _finite_or_none(before), _finite_or_none(after)

    def __str__(self) -> str:
        return self.text


def discover(
    data: Any,
    nominal: Model,
    tau: Optional[float] = None,
    run_column: Optional[str] = None,
    columns: Optional[Sequence[str]] = None,
    train: RunList = None,
    validation: RunList = None,
    test: RunList = None,
    seed: int = 0,
    segment: Optional[float] = None,
) -> Discovery:
    """Compares a nominal model with the data, names the effect it misses (friction, drag,
    stiffness, ...), adds it and refits (``ctsid discover``). ``segment`` cuts long runs into
    pieces of that many seconds, as in :func:`identify`."""
    if not isinstance(nominal, Model):
        raise TypeError("nominal: a ctsid.Model (ctsid.load(path) reads a model file)")
    tau = _tau(tau, nominal)
    names, runs = _records(data, nominal.outputs + nominal.inputs, run_column, columns, tau)
    verdict, text, inner, before, after = _ctsid.discover(
        tau,
        names,
        runs,
        nominal._m,
        train=_run_list(train),
        validation=_run_list(validation),
        test=_run_list(test),
        seed=_int("seed", seed),
        segment=_segment(segment),
    )
    return Discovery(verdict, text, Model(inner), before, after)


def throttle_dataset(
    path: str,
    runs: int = 100,
    samples: int = 1000,
    tau: float = 0.003,
    noise: float = 0.03,
    seed: int = 1,
    truth: bool = False,
) -> None:
    """Writes the source paper's throttle experiment as CSV (``run,t,u,y``; with ``truth``
    also ``y_true`` and its exact derivatives): the data of ``ctsid demo etc``."""
    _ctsid.throttle_dataset(
        _path("path", path),
        _int("runs", runs, 1),
        _int("samples", samples, 1),
        _real("tau", tau),
        _real("noise", noise),
        _int("seed", seed),
        _flag("truth", truth),
    )
