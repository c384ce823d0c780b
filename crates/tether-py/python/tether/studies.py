"""Studies: stability maps, convergence over H and study files, here or on
an executor (a ``concurrent.futures`` executor or a ``dask.distributed.Client``).

A study is cut into jobs, one run each, by Tether's study code (the code of
``tether sweep`` and ``tether study``). Without an executor the jobs run here,
in parallel over the cores; with one, chunks of jobs go to its workers as the
study's TOML text and job indices, and their results come back as plain
tuples. Either way the same code puts them together, so the results are the
same, bit for bit, wherever the jobs ran.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from . import _tether

Progress = Callable[[int, int], Any]
AxisSpec = Union[str, Mapping[str, Any]]


class StabilityMap:
    """One variant's stability map. Arrays are indexed ``[j, i]``: row ``j``
    is ``y[j]``, column ``i`` is ``x[i]``.

    - ``label``: the variant's label; ``x``, ``y``: the axis values;
      ``x_label``, ``y_label``: the axis titles,
    - ``classes``: ``"stable"``, ``"unstable"`` or ``"failed"`` per cell,
    - ``stable``: a boolean array, ``classes == "stable"``,
    - ``reached``: the last time each run reached,
    - ``reasons``: why a cell is unstable or failed (``""`` when stable).
    """

    def __init__(self, raw: Dict[str, Any]) -> None:
        self.label: str = raw["label"]
        self.x = np.asarray(raw["x"], dtype=np.float64)
        self.y = np.asarray(raw["y"], dtype=np.float64)
        self.x_label: str = raw["x_label"]
        self.y_label: str = raw["y_label"]
        shape = (len(self.y), len(self.x))
        self.classes = np.asarray(raw["class"], dtype=object).reshape(shape)
        self.reached = np.asarray(raw["reached"], dtype=np.float64).reshape(shape)
        self.reasons = np.asarray(raw["reason"], dtype=object).reshape(shape)

    @property
    def stable(self) -> np.ndarray:
        """Whether each cell is stable (a boolean array)."""
        return self.classes == "stable"

    def counts(self) -> Dict[str, int]:
        """The number of stable, unstable and failed cells."""
        return {k: int((self.classes == k).sum()) for k in ("stable", "unstable", "failed")}

    def __repr__(self) -> str:
        c = self.counts()
        return (
            f"<tether.StabilityMap {self.label!r}: {len(self.x)}×{len(self.y)} cells, "
            f"{c['stable']} stable, {c['unstable']} unstable, {c['failed']} failed>"
        )


class ConvergenceCurve:
    """One variant's error over the macro-step size H.

    - ``label``; ``steps``: the H of each point (without the finest run when
      it is the reference),
    - ``error``: the global error per point (the largest of ``errors``; NaN
      when the run did not complete),
    - ``errors``: per point and measured column, max |value − reference|,
    - ``order``: the least-squares slope of log(error) over log(H), or None,
    - ``outcomes``: ``"completed"``, ``"diverged"`` or ``"failed"`` per
      point, ``messages`` why a run stopped (``""`` when it completed).
    """

    def __init__(self, raw: Dict[str, Any], columns: Sequence[str]) -> None:
        self.label: str = raw["label"]
        self.order: Optional[float] = raw["order"]
        self.columns: List[str] = list(columns)
        self.steps = np.asarray(raw["step"], dtype=np.float64)
        self.error = np.asarray(raw["error"], dtype=np.float64)
        self.errors = np.asarray(raw["errors"], dtype=np.float64).reshape(
            len(self.steps), len(self.columns)
        )
        self.outcomes: List[str] = list(raw["outcome"])
        self.messages: List[str] = list(raw["message"])

    def __repr__(self) -> str:
        order = "-" if self.order is None else f"{self.order:.2f}"
        return f"<tether.ConvergenceCurve {self.label!r}: {len(self.steps)} points, order {order}>"


class StudyResult:
    """The results of a study.

    - ``kind``: ``"stability"``, ``"convergence"`` or ``"series"``,
    - ``title``, ``summary``: the text ``tether study`` prints (also ``str(result)``),
    - ``files``: the files written (with ``out_dir``; else empty),
    - ``maps``: one :class:`StabilityMap` per variant (stability),
    - ``curves``: one :class:`ConvergenceCurve` per variant (convergence),
    - ``runs``: one :class:`tether.Result` per variant (series).
    """

    def __init__(self, raw: Dict[str, Any]) -> None:
        from . import Result

        self.kind: str = raw["kind"]
        self.title: str = raw["title"]
        self.summary: str = raw["summary"]
        self.files: List[str] = list(raw["files"])
        self.maps: List[StabilityMap] = [StabilityMap(m) for m in raw.get("maps", [])]
        self.curves: List[ConvergenceCurve] = [
            ConvergenceCurve(c, raw["columns"]) for c in raw.get("curves", [])
        ]
        self.runs = [Result(*r) for r in raw.get("runs", [])]

    def __str__(self) -> str:
        return self.summary

    def __repr__(self) -> str:
        n = len(self.maps) or len(self.curves) or len(self.runs)
        return f"<tether.StudyResult {self.kind} {self.title!r}: {n} variant(s)>"


# ---------------------------------------------------------------------------
# Running a plan


def _run_chunk(payload: str, indices: List[int]) -> Any:
    """One task on a worker: the jobs ``indices`` of the plan ``payload``, as
    plain tuples (any executor can send them back), or the failure's arguments."""
    try:
        return ("ok", _tether.run_jobs(payload, list(indices)))
    except _tether.Failure as f:
        return ("failed", f.args)


def _workers(executor: Any) -> int:
    """How many jobs the executor runs at once, as far as it tells."""
    n = getattr(executor, "_max_workers", None)
    if isinstance(n, int) and n > 0:
        return n
    info = getattr(executor, "scheduler_info", None)
    if callable(info):
        try:
            workers = info()["workers"].values()
            return max(1, sum(int(w.get("nthreads", 1)) for w in workers))
        except Exception:  # pragma: no cover - depends on the scheduler
            pass
    return os.cpu_count() or 1


def _distribute(plan: Any, executor: Any, chunksize: Optional[int], progress: Optional[Progress]) -> List[Any]:
    from . import Interrupted, _KINDS, TetherError

    n = plan.jobs
    if chunksize is None:
        # Enough tasks to balance the load (cells that diverge end early),
        # few enough that the executor's cost per task stays small.
        tasks = max(64, 4 * _workers(executor))
        chunksize = max(1, -(-n // tasks))
    if chunksize < 1:
        raise ValueError("chunksize must be at least 1")
    chunks = [list(range(i, min(n, i + chunksize))) for i in range(0, n, chunksize)]
    payload = plan.payload
    futures = [executor.submit(_run_chunk, payload, chunk) for chunk in chunks]
    results: List[Any] = []
    try:
        for future in futures:
            status, value = future.result()
            if status == "failed":
                kind, message, _ = value
                raise _KINDS.get(kind, TetherError)(message)
            results.extend(value)
            if progress is not None:
                progress(len(results), n)
    except KeyboardInterrupt:
        for future in futures:
            future.cancel()
        raise Interrupted(f"study interrupted after {len(results)} of {n} runs") from None
    except BaseException:
        for future in futures:
            future.cancel()
        raise
    return results


def _execute(
    make_plan: Callable[[], Any],
    executor: Any,
    chunksize: Optional[int],
    out_dir: Optional[Union[str, "os.PathLike[str]"]],
    progress: Optional[Progress],
) -> StudyResult:
    from . import _error

    out = None if out_dir is None else os.fspath(out_dir)
    try:
        plan = make_plan()
        if executor is None:
            raw = plan.run_local(out_dir=out, progress=progress)
        else:
            raw = plan.finish(_distribute(plan, executor, chunksize, progress), out_dir=out)
    except _tether.Failure as f:
        raise _error(f) from None
    return StudyResult(raw)


# ---------------------------------------------------------------------------
# The studies


def sweep_stability(
    system: Any,
    *,
    x: AxisSpec,
    y: AxisSpec,
    growth: Optional[float] = None,
    monitor: Optional[Sequence[str]] = None,
    executor: Any = None,
    chunksize: Optional[int] = None,
    out_dir: Optional[Union[str, "os.PathLike[str]"]] = None,
    name: Optional[str] = None,
    formats: Sequence[str] = ("svg",),
    progress: Optional[Progress] = None,
    **settings: Any,
) -> StudyResult:
    """A stability map, like ``tether sweep stability``: every cell of the
    grid ``x`` × ``y`` is one run, classified stable, unstable or failed.

    ``x`` and ``y`` are axes in the command-line form,
    ``"mass1.c,mass2.c=1e1..1e6:100:log"`` (targets ``=`` from ``..`` to
    ``:`` points, optionally ``:log``) or ``"step=1e-3,2e-3"`` (a list), or
    dicts like the study file's (``{"targets": ["mass1.c"], "from": 10,
    "to": 1e6, "points": 100, "scale": "log", "label": "spring c"}``).
    Targets are FMU parameters ``instance.parameter`` or ``step`` (H).
    ``growth`` and ``monitor``: a completed run is also unstable when a
    monitored column's peak over the last tenth of the run exceeds
    ``growth`` times its peak over the first tenth. ``settings`` are the
    keywords of :func:`tether.run` and hold for every cell.

    ``executor``: None runs the cells here over the cores; a
    ``concurrent.futures`` executor or a ``dask.distributed.Client`` runs
    chunks of ``chunksize`` cells (default: at least 64 tasks, 4 per
    worker) on its workers, which need the ``tether`` package and the FMUs
    at the same paths. The results are the same, bit for bit.
    ``out_dir`` writes ``<name>.csv``, ``.txt`` and the plots in
    ``formats`` as ``tether sweep`` does. ``progress(done, total)`` is
    called as runs finish. Ctrl-C raises :class:`tether.Interrupted`.
    """
    def plan() -> Any:
        return _tether.plan_sweep(
            "stability",
            **_study_source(system),
            x=x if isinstance(x, str) else dict(x),
            y=y if isinstance(y, str) else dict(y),
            growth=growth,
            monitor=list(monitor) if monitor else None,
            name=name,
            formats=list(formats),
            **_settings(settings),
        )

    return _execute(plan, executor, chunksize, out_dir, progress)


def sweep_convergence(
    system: Any,
    *,
    steps: Sequence[float],
    columns: Sequence[str],
    reference: str = "finest",
    executor: Any = None,
    chunksize: Optional[int] = None,
    out_dir: Optional[Union[str, "os.PathLike[str]"]] = None,
    name: Optional[str] = None,
    formats: Sequence[str] = ("svg",),
    progress: Optional[Progress] = None,
    **settings: Any,
) -> StudyResult:
    """The global error of ``columns`` over the macro-step sizes ``steps``,
    like ``tether sweep convergence``, with the fitted order.

    ``reference``: ``"finest"`` (the run with the smallest H, which is then
    not a point of the curve), ``"two-mass-oscillator"`` (the closed form of
    the paper's oscillator) or the path of a results CSV. ``settings``,
    ``executor``, ``chunksize``, ``out_dir``, ``name``, ``formats`` and
    ``progress`` as in :func:`sweep_stability`; each H is one job.
    """
    def plan() -> Any:
        return _tether.plan_sweep(
            "convergence",
            **_study_source(system),
            steps=[float(h) for h in steps],
            columns=list(columns),
            reference=os.fspath(reference),
            name=name,
            formats=list(formats),
            **_settings(settings),
        )

    return _execute(plan, executor, chunksize, out_dir, progress)


def study(
    file: Union[str, "os.PathLike[str]"],
    *,
    executor: Any = None,
    chunksize: Optional[int] = None,
    out_dir: Optional[Union[str, "os.PathLike[str]"]] = None,
    progress: Optional[Progress] = None,
) -> StudyResult:
    """Run a study file (docs/studies.md), like ``tether study FILE``:
    its variants and one ``[series]``, ``[convergence]`` or ``[stability]``.
    ``executor``, ``chunksize``, ``out_dir`` (files named by the study's
    ``output``, plots in its ``formats``) and ``progress`` as in
    :func:`sweep_stability`."""
    path = os.fspath(file)
    return _execute(lambda: _tether.plan_study(path), executor, chunksize, out_dir, progress)


def _study_source(system: Any) -> Dict[str, Any]:
    from . import System

    if isinstance(system, System):
        return {"text": system.to_toml()}
    if isinstance(system, (str, os.PathLike)):
        # Absolute, so that the plan's FMU paths are too (workers may run
        # in another folder).
        return {"path": os.path.abspath(os.fspath(system))}
    raise TypeError(f"system must be a path or a tether.System, not {type(system).__name__}")


def _settings(settings: Mapping[str, Any]) -> Dict[str, Any]:
    return {k: v for k, v in settings.items() if v is not None}
