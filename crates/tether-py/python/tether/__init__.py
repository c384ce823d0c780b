"""Tether from Python: couple FMI 2.0 co-simulation FMUs through algebraic
constraints with the predictor/corrector methods of Schweizer & Lu (2015).

The coupled master, the FMU import and the numerics are Tether's Rust library;
this package calls it in-process (no `tether` binary, no CSV in between).

    >>> import tether
    >>> result = tether.run("examples/oscillator.toml", step=1e-3)
    >>> result["mass1.x"]            # NumPy float64 array, one value per macro point
    >>> result.to_numpy()            # structured array like fmpy's simulate_fmu result

Entry points:

- :func:`run` a system file or :class:`System` to its stop time,
- :class:`Simulation` to advance it step by step and read outputs between steps,
- :func:`simulate` one FMU on its own and :func:`info` for its model description,
- :class:`System` to build (or load and change) a system in code,
- :func:`sweep_stability`, :func:`sweep_convergence` and :func:`study` for
  studies, here or on a ``concurrent.futures`` executor or a Dask cluster,
- :func:`run_many` for many runs of one system.

Errors are :class:`TetherError` subclasses with the one-line messages of the
``tether`` command; a run that stops early carries its partial
:class:`Result` in ``err.result``.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Union

import numpy as np

try:  # Python 3.11+: a loaded system keeps the file's order of sections
    import tomllib
except ImportError:  # pragma: no cover
    tomllib = None

from . import _tether

__version__: str = _tether.__version__

# Isolated instances (isolation = "process", docs/reliability.md) run in host
# processes started as `python -m tether._fmi_host`: the package needs no
# executable of its own. TETHER_FMI_HOST, when set, still comes first.
_tether.use_fmi_host(sys.executable, ["-m", "tether._fmi_host"])

# An in-process FMU's exit()/abort() ends the process with one line and a
# non-zero status (docs/python.md); in a child of os.fork() (a multiprocessing
# worker) too, but never in a process an FMU forked itself.
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_tether.adopt_exit_hook)

__all__ = [
    "run",
    "run_many",
    "sweep_stability",
    "sweep_convergence",
    "study",
    "StudyResult",
    "StabilityMap",
    "ConvergenceCurve",
    "simulate",
    "info",
    "export_fmu",
    "Simulation",
    "System",
    "Result",
    "TetherError",
    "FmuError",
    "SystemFileError",
    "SettingsError",
    "DivergenceError",
    "Interrupted",
    "Note",
]

PathLike = Union[str, "os.PathLike[str]"]
ParameterValue = Union[bool, int, float, str]


# ---------------------------------------------------------------------------
# Errors


class Note(UserWarning):
    """What the ``tether`` command prints as ``note:`` before a run, such as a
    direct-feedthrough loop of signal connections closed only at macro
    points: issued with :func:`warnings.warn` by :func:`run` and
    :class:`Simulation`, and kept in ``stats["notes"]``. Silence it with
    ``warnings.simplefilter("ignore", tether.Note)``."""


def _notes(stats: Dict[str, Any]) -> None:
    for note in stats.get("notes", []):
        warnings.warn(note, Note, stacklevel=3)
    # What the command prints as ``warning:``: a parameter an FMU changed in
    # its initialization (docs/fmi-import.md).
    for warning in stats.get("warnings", []):
        warnings.warn(warning, UserWarning, stacklevel=3)


class TetherError(Exception):
    """Any failure of Tether. ``str(err)`` is the one-line message the
    ``tether`` command prints; ``err.result`` is the partial :class:`Result`
    of a run that stopped early (every accepted step), else ``None``."""

    result: Optional["Result"]

    def __init__(self, message: str, result: Optional["Result"] = None) -> None:
        super().__init__(message)
        self.result = result


class FmuError(TetherError):
    """An FMU cannot be loaded, lacks a needed capability, or an FMI call failed."""


class SystemFileError(TetherError):
    """The system (file or :class:`System`) is malformed or does not fit its FMUs."""


class SettingsError(TetherError, ValueError):
    """A setting is not valid: an unknown method or a parameter of another
    method, a malformed ``parameters`` target, or a number out of its range
    (step, stop time, method parameter …, also when the system file sets it)."""


class DivergenceError(TetherError):
    """The coupling diverged (a value became non-finite or exploded), the
    interface Jacobian became singular, or an iterated step did not converge
    with ``[signals] strict``."""


class Interrupted(TetherError, KeyboardInterrupt):
    """The run was stopped by Ctrl-C (or another signal handler that raised).
    Also a :class:`KeyboardInterrupt`; ``err.result`` holds the steps so far."""


_KINDS = {
    "fmu": FmuError,
    "system": SystemFileError,
    "settings": SettingsError,
    "divergence": DivergenceError,
    "interrupted": Interrupted,
}


def _error(failure: BaseException, partial: Optional["Result"] = None) -> TetherError:
    kind, message, raw = failure.args
    if raw is not None:
        partial = Result(*raw)
    return _KINDS.get(kind, TetherError)(message, partial)


# ---------------------------------------------------------------------------
# Results


class Result:
    """The results of a run: one row per accepted macro point.

    ``columns`` are the names after ``time``, as in the CSV of ``tether run``:
    every output (Real, then Integer, then Boolean, as numbers, then String,
    as text) as ``<instance>.<variable>``, then the multipliers
    (``<constraint>.lambda``), then the residuals (``<constraint>.g``).

    ``result[name]`` is a NumPy float64 array of one column (``"time"`` too;
    an object array of ``str`` for a String output), :meth:`to_numpy` the
    whole table as a structured array whose fields are ``time`` and the
    columns (the shape of fmpy's ``simulate_fmu`` result; String outputs are
    object fields),
    ``complete`` whether the run reached its stop time, ``stats`` the run's
    counters (see docs/python.md).
    """

    def __init__(
        self,
        columns: Sequence[str],
        data: bytes,
        stats: Dict[str, Any],
        texts: Optional[Dict[str, List[str]]] = None,
    ) -> None:
        self.columns: List[str] = list(columns)
        self.stats: Dict[str, Any] = stats
        self._dtype = np.dtype([("time", "f8")] + [(c, "f8") for c in self.columns])
        # A view of the bytes the master produced: no copy.
        self._table = np.frombuffer(data, dtype=self._dtype)
        if texts:
            # String outputs: object fields holding the texts (a copy).
            self._dtype = np.dtype(
                [("time", "f8")] + [(c, "O" if c in texts else "f8") for c in self.columns]
            )
            table = np.empty(len(self._table), dtype=self._dtype)
            for name in ["time"] + self.columns:
                if name in texts:
                    table[name] = np.array(texts[name], dtype=object)
                else:
                    table[name] = self._table[name]
            self._table = table
        self._index = {name: i for i, name in enumerate(self.columns)}
        #: Where :func:`run` with ``client=`` placed each isolated instance:
        #: ``{name: {"worker": address, "host": "tcp://ADDR:PORT"}}``.
        self.placement: Dict[str, Dict[str, str]] = {}

    @property
    def complete(self) -> bool:
        """Whether the run reached its stop time."""
        return self.stats.get("stop_reason") == "completed"

    @property
    def time(self) -> np.ndarray:
        """The macro times T_n."""
        return np.array(self._table["time"])

    def __getitem__(self, name: str) -> np.ndarray:
        if name != "time" and name not in self._index:
            raise KeyError(f"no column '{name}'; columns are time, {', '.join(self.columns)}")
        return np.array(self._table[name])

    def __contains__(self, name: object) -> bool:
        return name == "time" or name in self._index

    def __iter__(self) -> Iterator[str]:
        return iter(["time"] + self.columns)

    def __len__(self) -> int:
        """The number of rows (macro points, the start included)."""
        return len(self._table)

    def to_numpy(self) -> np.ndarray:
        """A structured array (a copy) with fields ``time`` and the columns,
        as fmpy's ``simulate_fmu`` returns; fmpy's ``write_csv`` and
        ``plot_result`` accept it."""
        return self._table.copy()

    def to_pandas(self) -> "Any":
        """A pandas DataFrame with a ``time`` column and the columns (needs pandas)."""
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Result.to_pandas() needs pandas: pip install pandas") from e
        return pd.DataFrame(self.to_numpy())

    def __repr__(self) -> str:
        end = self._table["time"][-1] if len(self._table) else float("nan")
        state = "complete" if self.complete else f"incomplete: {self.stats.get('stop_reason')}"
        return f"<tether.Result {len(self)} rows × {len(self.columns) + 1} columns, t ≤ {end} ({state})>"


# ---------------------------------------------------------------------------
# Systems


def _source(system: Union[PathLike, "System"]) -> Dict[str, Any]:
    if isinstance(system, System):
        return {"text": system.to_toml()}
    if isinstance(system, (str, os.PathLike)):
        return {"path": os.fspath(system)}
    raise TypeError(f"system must be a path or a tether.System, not {type(system).__name__}")


def _overrides(**given: Any) -> Dict[str, Any]:
    return {k: v for k, v in given.items() if v is not None}


def _one_of(name: str, value: Any, alias: str, alias_value: Any) -> Any:
    """A setting given by its own name or by fmpy's, not both."""
    if value is not None and alias_value is not None:
        raise TypeError(f"{name} and {alias} are the same setting; give one of them")
    return alias_value if value is None else value


def _patterns(value: Union[str, Sequence[str]]) -> List[str]:
    """Column patterns from a list or a comma-separated string (commas inside
    brackets belong to the name, as on the command line)."""
    items = [value] if isinstance(value, str) else list(value)
    out: List[str] = []
    for item in items:
        depth, current = 0, ""
        for c in item:
            if c == "[":
                depth += 1
            elif c == "]":
                depth = max(depth - 1, 0)
            elif c == "," and depth == 0:
                out.append(current)
                current = ""
                continue
            current += c
        out.append(current)
    return [p.strip() for p in out if p.strip()]


def _ordered_like(value: Any, raw: Any) -> Any:
    """`value` (a loaded system's dict) with its keys in the order of `raw`
    (the file as tomllib reads it), the keys the file does not have last."""
    if isinstance(value, dict) and isinstance(raw, dict):
        keys = [k for k in raw if k in value] + [k for k in value if k not in raw]
        return {k: _ordered_like(value[k], raw.get(k)) for k in keys}
    if isinstance(value, list) and isinstance(raw, list) and len(value) == len(raw):
        return [_ordered_like(v, r) for v, r in zip(value, raw)]
    return value


class System:
    """A system built in code: FMU instances, constraints, joints, coupling
    variables, the time grid and the method; the same content as a system file
    (docs/system-file.md). Every method returns the system, so calls chain::

        sys = (tether.System("two masses")
               .experiment(stop=1.0, step=1e-3)
               .method("baumgarte", beta=2e-3, gamma=1e-6)
               .add_instance("mass1", "oscillator.fmu", {"m": 1.0, "v0": 100.0})
               .add_instance("mass2", "oscillator.fmu", {"m": 2.0, "v0": 100.0})
               .add_constraint("link", position="mass2.x - mass1.x",
                               velocity="mass2.v - mass1.v",
                               acceleration="mass2.a - mass1.a",
                               drives="mass1.F - mass2.F"))
        tether.run(sys)

    Relative FMU paths are made absolute when added (against the current
    directory) or loaded (against the system file's folder).
    """

    def __init__(self, name: Optional[str] = None) -> None:
        self._data: Dict[str, Any] = {
            "name": name,
            "experiment": None,
            "method": None,
            "coupling": {},
            "instance": [],
            "constraint": [],
            "joint": [],
            "coupling_variable": [],
            "connection": [],
        }

    @classmethod
    def from_file(cls, path: PathLike) -> "System":
        """Load a system file (raises :class:`SystemFileError` as ``tether run`` would)."""
        try:
            data = _tether.load_system(os.fspath(path))
        except _tether.Failure as f:
            raise _error(f) from None
        system = cls(data.get("name"))
        # Every section the file has, the lists copied so they can be changed.
        for key, value in data.items():
            if key != "name":
                system._data[key] = list(value) if isinstance(value, list) else value
        for inst in system._data["instance"]:
            inst["fmu"] = os.path.abspath(inst["fmu"])
        # The file's order of sections and of the keys in each (to_toml keeps it).
        if tomllib is not None:
            with open(path, "rb") as f:
                system._data = _ordered_like(system._data, tomllib.load(f))
        return system

    @property
    def name(self) -> Optional[str]:
        return self._data["name"]

    @property
    def instances(self) -> List[Dict[str, Any]]:
        """The instances as dicts (``name``, ``fmu``, ``parameters``); changeable."""
        return self._data["instance"]

    def experiment(
        self, stop: float, step: float, start: float = 0.0, tolerance: Optional[float] = None
    ) -> "System":
        """The time grid ``T_n = start + n·step`` up to ``stop``."""
        self._data["experiment"] = _overrides(start=float(start), stop=float(stop), step=float(step), tolerance=tolerance)
        return self

    def method(self, kind: str, **parameters: float) -> "System":
        """The coupling method: ``"baumgarte"`` (beta, gamma), ``"weighted"``
        (a, b) or ``"explicit"`` (mu)."""
        self._data["method"] = {"kind": kind, **{k: float(v) for k, v in parameters.items()}}
        return self

    def coupling(self, **settings: Any) -> "System":
        """Settings of every method: ``order`` (0, 1, 2), ``epsilon``,
        ``max_condition``, ``divergence_factor``, ``parallel`` ("auto", "on", "off"),
        ``threads`` (the main thread included)."""
        self._data["coupling"].update(settings)
        return self

    def add_instance(
        self,
        name: str,
        fmu: PathLike,
        parameters: Optional[Mapping[str, ParameterValue]] = None,
        isolation: Optional[str] = None,
        call_timeout: Optional[float] = None,
        host: Optional[str] = None,
        token_file: Optional[PathLike] = None,
        fmu_on_host: Optional[str] = None,
        resources: Optional[Mapping[str, float]] = None,
        step: Optional[float] = None,
        parallel: Optional[bool] = None,
        fmi_type: Optional[str] = None,
        integrator: Optional[Mapping[str, Any]] = None,
    ) -> "System":
        """An FMU instance named ``name`` (the column prefix) with start values;
        ``step`` is its own communication step, a whole multiple of the
        system's (docs/system-file.md, "Per-instance steps");
        ``isolation="process"`` runs it in a host process of its own and
        ``call_timeout`` (seconds) bounds each FMI call (docs/reliability.md).
        ``host="tcp://ADDR:PORT"`` with ``token_file`` runs it on a ``tether
        host`` (docs/remote.md); ``fmu_on_host`` names an FMU already there.
        ``resources`` (``{"licence": 1}``) are what a Dask worker must have
        to host the instance when :func:`run` is given ``client=``.
        ``parallel=False`` keeps its runs on the main thread under
        ``[coupling] parallel`` (an FMU bound to the thread that made it).
        ``fmi_type`` is the FMI interface it runs: ``"auto"`` (default),
        ``"co_simulation"`` or ``"model_exchange"`` (fmpy's ``"CoSimulation"``
        and ``"ModelExchange"`` too); ``integrator`` the model-exchange
        integrator's settings, e.g. ``{"method": "bdf", "rtol": 1e-8}``
        (docs/system-file.md, "Model exchange")."""
        inst: Dict[str, Any] = {"name": name, "fmu": os.path.abspath(os.fspath(fmu))}
        if parameters:
            inst["parameters"] = dict(parameters)
        if isolation is not None:
            inst["isolation"] = isolation
        if call_timeout is not None:
            inst["call_timeout"] = float(call_timeout)
        if step is not None:
            inst["step"] = float(step)
        if host is not None:
            inst["host"] = host
        if token_file is not None:
            inst["token_file"] = os.path.abspath(os.fspath(token_file))
        if fmu_on_host is not None:
            inst["fmu_on_host"] = fmu_on_host
        if resources is not None:
            inst["resources"] = dict(resources)
        if parallel is not None:
            inst["parallel"] = bool(parallel)
        if fmi_type is not None:
            inst["fmi_type"] = fmi_type
        if integrator is not None:
            inst["integrator"] = dict(integrator)
        self._data["instance"].append(inst)
        return self

    def add_connection(
        self,
        source: str,
        target: str,
        gain: Optional[float] = None,
        offset: Optional[float] = None,
    ) -> "System":
        """A signal connection: the output ``source`` (``"instance.variable"``)
        is handed to the input ``target`` at macro points, as
        ``gain·value + offset`` (docs/system-file.md, ``[[connection]]``)."""
        self._data["connection"].append(
            _overrides(**{"from": source, "to": target, "gain": gain, "offset": offset})
        )
        return self

    def signals(
        self,
        scheme: Optional[str] = None,
        *,
        tolerance: Optional[float] = None,
        iterations: Optional[int] = None,
        solver: Optional[str] = None,
        strict: Optional[bool] = None,
    ) -> "System":
        """The ``[signals]`` table: the order of signal connections
        (``scheme``: ``"jacobi"`` or ``"gauss_seidel"``), the ``tolerance`` on
        exchanged values, and iterated steps: at most ``iterations``
        repetitions (``solver="fixed_point"``, the default) or Newton updates
        (``solver="newton"``, without ``scheme``) per macro step; ``strict``
        fails the run on a step that does not converge."""
        self._data["signals"] = _overrides(
            scheme=scheme,
            tolerance=None if tolerance is None else float(tolerance),
            iterations=None if iterations is None else int(iterations),
            solver=solver,
            strict=None if strict is None else bool(strict),
        )
        return self

    def output(
        self, interval: Optional[float] = None, variables: Optional[Sequence[str]] = None
    ) -> "System":
        """What is recorded: every ``interval`` (a whole multiple of the step)
        and the columns matching ``variables`` (``*`` matches any characters)."""
        self._data["output"] = _overrides(
            interval=None if interval is None else float(interval),
            variables=None if variables is None else list(variables),
        )
        return self

    def add_constraint(
        self,
        name: str,
        position: str,
        drives: str,
        velocity: Optional[str] = None,
        acceleration: Optional[str] = None,
        initial: Union[float, str, None] = None,
    ) -> "System":
        """A scalar constraint g = 0 (linear expressions of outputs on position,
        velocity, acceleration level); its multiplier λ drives the inputs of
        ``drives``; ``initial`` is a number or ``"consistent"`` (default)."""
        self._data["constraint"].append(
            _overrides(
                name=name,
                position=position,
                velocity=velocity,
                acceleration=acceleration,
                drives=drives,
                initial=initial,
            )
        )
        return self

    def add_joint(self, name: str, kind: str, i: str, j: str, **geometry: Any) -> "System":
        """A joint between markers ``i`` and ``j`` (``"instance.marker"``) of
        ``kind`` (revolute, universal, …); ``geometry``: plane, axis_i, ref_i,
        axis_j, ref_j, offset_i, offset_j, multipliers, initial (docs/joints.md)."""
        self._data["joint"].append(_overrides(name=name, kind=kind, i=i, j=j, **geometry))
        return self

    def add_coupling_variable(
        self, name: str, drives: str, value: str, initial: Union[float, str, None] = None
    ) -> "System":
        """An input that must equal an expression of outputs at every macro point."""
        self._data["coupling_variable"].append(
            _overrides(name=name, drives=drives, value=value, initial=initial)
        )
        return self

    def to_dict(self) -> Dict[str, Any]:
        """The system as a dict shaped like the system file."""
        out: Dict[str, Any] = {}
        for key, value in self._data.items():
            if value is None or value == [] or value == {}:
                continue
            out[key] = value
        return out

    def to_toml(self) -> str:
        """The system file text (TOML), its sections in the order they were
        added (or, for a loaded system, of the file)."""
        if self._data["experiment"] is None:
            raise SystemFileError("system: no experiment; call System.experiment(stop=…, step=…)")
        data = self.to_dict()
        # TOML wants the top-level keys before the first table; each section
        # is then written on its own, in order.
        top = {k: v for k, v in data.items() if not isinstance(v, (dict, list))}
        parts = [_tether.dump_toml(top)] if top else []
        parts += [_tether.dump_toml({k: v}) for k, v in data.items() if k not in top]
        return "\n".join(p.strip("\n") + "\n" for p in parts if p.strip())

    def save(self, path: PathLike) -> None:
        """Write the system file."""
        with open(path, "w", encoding="utf-8") as f:
            f.write(self.to_toml())

    def __repr__(self) -> str:
        names = ", ".join(i["name"] for i in self.instances)
        return f"<tether.System {self.name or ''!s} instances: {names}>"


# ---------------------------------------------------------------------------
# Runs


def run(
    system: Union[PathLike, System],
    *,
    stop: Optional[float] = None,
    step: Optional[float] = None,
    method: Optional[str] = None,
    beta: Optional[float] = None,
    gamma: Optional[float] = None,
    a: Optional[float] = None,
    b: Optional[float] = None,
    mu: Optional[float] = None,
    order: Optional[int] = None,
    epsilon: Optional[float] = None,
    parallel: Union[str, bool, None] = None,
    threads: Optional[int] = None,
    divergence_factor: Optional[float] = None,
    parameters: Optional[Mapping[str, ParameterValue]] = None,
    progress: Optional[Callable[[int, int], Any]] = None,
    index: Optional[int] = None,
    iterations: Optional[int] = None,
    iteration_tol: Optional[float] = None,
    jacobian: Optional[str] = None,
    step_rtol: Optional[float] = None,
    step_atol: Optional[float] = None,
    isolate: Optional[bool] = None,
    call_timeout: Optional[float] = None,
    output_interval: Optional[float] = None,
    output_variables: Union[str, Sequence[str], None] = None,
    stop_time: Optional[float] = None,
    start_values: Optional[Mapping[str, ParameterValue]] = None,
    output: Union[str, Sequence[str], None] = None,
    client: Any = None,
) -> Result:
    """Run a coupled system to its stop time, like ``tether run``.

    ``system`` is a system-file path, an SSP (an ``.ssp`` archive, a
    ``SystemStructure.ssd`` or a folder holding one, read as ``tether run``
    reads it, docs/ssp.md) or a :class:`System`. The keyword arguments
    override the system's settings as the CLI flags do:

    - ``stop``, ``step``: stop time and macro-step size H,
    - ``method``: ``"baumgarte"``, ``"weighted"`` or ``"explicit"``, with
      ``beta``/``gamma`` (baumgarte), ``a``/``b`` (weighted), ``mu`` (explicit),
    - ``order``: degree k of the coupling polynomials (0, 1, 2),
    - ``epsilon``: finite-difference increment of the interface Jacobian,
    - ``parallel``: the runs of a step on worker threads, ``"auto"``,
      ``"on"``, ``"off"`` (or True/False); ``threads``: how many, the main
      thread included,
    - ``parameters``: FMU start values, ``{"mass1.m": 2.0}`` (``--set``),
    - ``index``: index level 1, 2 or 3 of baumgarte or weighted (``--index``),
    - ``iterations``, ``iteration_tol``, ``jacobian``: the corrections per
      macro step and when the Jacobian is made (``--iterations`` …),
    - ``step_rtol``, ``step_atol``: adaptive macro steps,
    - ``isolate``, ``call_timeout``: every instance in a host process of its
      own, the longest an FMI call may take (``--isolate``, ``--call-timeout``),
    - ``output_interval``, ``output_variables``: the recorded grid and column
      patterns (``--output-interval``, ``--output-variables``).

    fmpy's names are accepted where they mean the same: ``stop_time`` for
    ``stop``, ``start_values`` for ``parameters``, ``output`` for
    ``output_variables``; giving both names of one setting is a ``TypeError``.

    ``client``, a ``dask.distributed.Client``, places the host of every
    isolated instance (``isolation = "process"``, ``isolate=True``, or an
    instance with ``resources``) on a worker of its cluster, one that has the
    instance's ``resources``; the master runs here and connects to each
    host on its worker's address with a token made for the run
    (docs/remote.md). ``result.placement`` then names each placed
    instance's ``worker`` and ``host``; the hosts end with the run.

    ``progress(step, total)`` is called every 50 ms while the run goes on
    (an exception from it stops the run as Ctrl-C does).

    The results are the same, bit for bit, as the CSV of ``tether run``. The
    GIL is released while the master runs; Ctrl-C stops the run after the
    current macro step and raises :class:`Interrupted` with the partial
    result. A run that diverges raises :class:`DivergenceError` with the
    partial result in ``err.result``.
    """
    if client is not None:
        given = {k: v for k, v in locals().items() if k not in ("system", "client")}
        from ._dask import run_placed

        return run_placed(system, client, given, run)
    stop = _one_of("stop", stop, "stop_time", stop_time)
    parameters = _one_of("parameters", parameters, "start_values", start_values)
    output_variables = _one_of("output_variables", output_variables, "output", output)
    kw = _overrides(
        stop=stop, step=step, method=method, beta=beta, gamma=gamma, a=a, b=b, mu=mu,
        order=order, epsilon=epsilon, parallel=parallel, threads=threads,
        divergence_factor=divergence_factor, parameters=parameters, index=index,
        iterations=iterations, iteration_tol=iteration_tol, jacobian=jacobian,
        step_rtol=step_rtol, step_atol=step_atol, isolate=isolate, call_timeout=call_timeout,
        output_interval=output_interval,
        output_variables=None if output_variables is None else _patterns(output_variables),
    )
    try:
        raw = _tether.run(**_source(system), progress=progress, **kw)
    except _tether.Failure as f:
        partial = f.args[2] if len(f.args) > 2 else None
        if partial:
            _notes(partial[2])
        raise _error(f) from None
    _notes(raw[2])
    return Result(*raw)


def _run_raw(source: Dict[str, Any], overrides: Dict[str, Any]) -> Any:
    """One run in a worker: the raw results, or the failure's arguments
    (plain tuples, so that any executor can send them back)."""
    try:
        return ("ok", _tether.run(**source, **_overrides(**overrides)))
    except _tether.Failure as f:
        return ("failed", f.args)


def run_many(
    system: Union[PathLike, System],
    variants: Sequence[Mapping[str, Any]],
    *,
    executor: Any = None,
    errors: str = "raise",
) -> List[Union[Result, TetherError]]:
    """Run ``system`` once per dict of overrides in ``variants`` (the keywords
    of :func:`run`) and return the results in the same order.

    ``executor`` is anything with ``submit(fn, *args)`` returning futures with
    ``result()``: a ``concurrent.futures`` executor (``ProcessPoolExecutor``
    runs them in parallel processes; a thread pool gains little, each run
    holds a core) or a ``dask.distributed.Client``. Without one the
    runs are made here, one after the other. Each run is the same as
    :func:`run` with those overrides, bit for bit, wherever it is made.

    ``errors="raise"`` raises the first failure (in the order of
    ``variants``); ``errors="return"`` puts the :class:`TetherError` (with its
    partial ``result``) into the list instead, as a stability map needs.
    """
    if errors not in ("raise", "return"):
        raise ValueError("errors must be 'raise' or 'return'")
    if isinstance(system, System):
        source: Dict[str, Any] = {"text": system.to_toml()}
    else:
        # Workers may run elsewhere in the file system: an absolute path.
        source = {"path": os.path.abspath(os.fspath(system))}
    if executor is None:
        raws = [_run_raw(source, dict(v)) for v in variants]
    else:
        futures = [executor.submit(_run_raw, source, dict(v)) for v in variants]
        raws = [f.result() for f in futures]
    out: List[Union[Result, TetherError]] = []
    for status, payload in raws:
        if status == "ok":
            out.append(Result(*payload))
            continue
        kind, message, partial = payload
        err = _KINDS.get(kind, TetherError)(message, Result(*partial) if partial else None)
        if errors == "raise":
            raise err
        out.append(err)
    return out


class Simulation:
    """A coupled run advanced step by step; outputs can be read between steps::

        sim = tether.Simulation("examples/oscillator.toml")
        while sim.time < 0.5:
            sim.step()
        print(sim.outputs["mass1.x"], sim.unknowns)
        sim.run_until(1.0)
        result = sim.result()

    Takes the same arguments as :func:`run` (a system file, an SSP or a
    :class:`System`). The run is instantiated (FMUs
    loaded, initialised, consistent multipliers solved) on construction.
    The steps are the same as those of :func:`run`: ``sim.result()`` after
    the last step equals ``tether.run(...)`` bit for bit.
    """

    def __init__(self, system: Union[PathLike, System], **overrides: Any) -> None:
        kw = _overrides(**overrides)
        try:
            self._sim = _tether.Simulation(**_source(system), **kw)
        except _tether.Failure as f:
            raise _error(f) from None
        _notes(self._sim.stats())
        self._columns: List[str] = self._sim.columns

    @property
    def columns(self) -> List[str]:
        """Column names after ``time`` (as in :class:`Result`)."""
        return list(self._columns)

    @property
    def time(self) -> float:
        """The current macro time T_N."""
        return self._get("time")

    @property
    def steps(self) -> int:
        """Macro steps made so far."""
        return self._sim.steps

    @property
    def total_steps(self) -> int:
        """Macro steps from the start to the stop time."""
        return self._get("total_steps")

    @property
    def done(self) -> bool:
        """Whether the stop time is reached."""
        return self._sim.steps >= self._get("total_steps")

    @property
    def outputs(self) -> Dict[str, float]:
        """The values of the current point by column name: outputs,
        multipliers and residuals."""
        return dict(zip(self._columns, self._get("values")))

    @property
    def values(self) -> np.ndarray:
        """The values of the current point in column order."""
        return np.array(self._get("values"), dtype=np.float64)

    @property
    def unknowns(self) -> np.ndarray:
        """The coupling unknowns u_N (multipliers of constraints and joints,
        coupling variables), in the order of their columns."""
        return np.array(self._get("unknowns"), dtype=np.float64)

    @property
    def stats(self) -> Dict[str, Any]:
        """The counters so far (the schema of :attr:`Result.stats`)."""
        return self._sim.stats()

    def result(self) -> Result:
        """Every point so far as a :class:`Result`."""
        return Result(*self._sim.result())

    def _advance(self, count: int) -> int:
        try:
            return self._sim.advance(count)
        except _tether.Failure as f:
            raise _error(f, self.result()) from None

    def _get(self, name: str) -> Any:
        try:
            return getattr(self._sim, name)
        except _tether.Failure as f:
            raise _error(f) from None

    def step(self) -> float:
        """Advance one macro step; returns the new time. Raises
        :class:`TetherError` at the stop time."""
        if self._advance(1) == 0:
            raise TetherError(f"the simulation is at its stop time t = {self.time}")
        return self.time

    def set_parameter(self, name: str, value: ParameterValue) -> None:
        """Set ``name`` (``"instance.variable"``) to ``value`` before the next
        step, where FMI 2.0 allows it: an input the coupling does not drive,
        or a parameter with variability "tunable". A fixed parameter (settable
        only before initialization: give it in ``parameters=``), an output,
        an input the coupling drives, a value of the wrong type or outside the
        variable's min/max raise :class:`SettingsError`. The value holds from
        the current time on; outputs that depend on it show it from the next
        point on (:attr:`outputs` are those of the accepted step)."""
        try:
            self._sim.set_parameter(name, value)
        except _tether.Failure as f:
            raise _error(f) from None

    def run_until(self, t: float) -> float:
        """Advance to the first macro point at or after ``t`` (at most to the
        stop time); returns the new time. Ctrl-C raises :class:`Interrupted`."""
        try:
            count = self._sim.steps_to(t)
        except _tether.Failure as f:
            raise _error(f) from None
        self._advance(count)
        return self.time

    def run(self) -> Result:
        """Advance to the stop time and return every point as a :class:`Result`."""
        self.run_until(math.inf)
        return self.result()

    def close(self) -> None:
        """Free the FMU instances and remove their unpacked folders now (else
        when the object is collected). The results so far (:meth:`result`,
        :attr:`stats`) stay; stepping afterwards raises :class:`TetherError`."""
        self._sim.close()

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._sim.closed

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        if self.closed:
            return f"<tether.Simulation closed after {self.steps} steps>"
        return f"<tether.Simulation t = {self.time}, step {self.steps} of {self.total_steps}>"


# ---------------------------------------------------------------------------
# One FMU


def simulate(
    fmu: PathLike,
    *,
    start: Optional[float] = None,
    stop: Optional[float] = None,
    step: Optional[float] = None,
    tolerance: Optional[float] = None,
    parameters: Optional[Mapping[str, ParameterValue]] = None,
    fmi_type: Optional[str] = None,
) -> Result:
    """Run one FMU (FMI 2.0 or 3.0) at a fixed communication step, like
    ``tether simulate`` (the same simulation) or fmpy's ``simulate_fmu``:
    every non-String output at every step, an array one column per element
    (``y[1]``, ``A[2,3]``). ``fmi_type`` is fmpy's ``"CoSimulation"`` or
    ``"ModelExchange"`` (default: co-simulation where the FMU has it); with
    model exchange the built-in integrator (docs/fmi-import.md) takes
    ``tolerance`` as its relative tolerance.
    ``start``, ``stop``, ``step`` and ``tolerance`` default to the FMU's
    DefaultExperiment (else 0, start + 1, (stop − start)/500); ``parameters``
    are start values by variable name. A NaN or infinite output raises
    :class:`TetherError` with the rows before it as ``err.result``; an FMU's
    request to end the simulation ends it normally, noted in
    ``stats["termination"]``."""
    try:
        raw = _tether.simulate(
            os.fspath(fmu),
            start=start,
            stop=stop,
            step=step,
            tolerance=tolerance,
            parameters=dict(parameters) if parameters else None,
            fmi_type=fmi_type,
        )
    except _tether.Failure as f:
        raise _error(f) from None
    _notes(raw[2])
    return Result(*raw)


def info(fmu: PathLike) -> Dict[str, Any]:
    """An FMU's model description as a dict with fmpy's attribute names:
    ``modelName``, ``guid``, ``fmiVersion``, ``coSimulation`` (the
    capability flags), ``defaultExperiment`` and ``modelVariables`` (dicts
    with ``name``, ``valueReference``, ``causality``, ``variability``,
    ``initial``, ``type``, ``start``, ``unit``, ``description``)."""
    try:
        return _tether.info(os.fspath(fmu))
    except _tether.Failure as f:
        raise _error(f) from None


#: The exported FMU's binary (libtether_fmu_export.so), package data of the
#: wheel: tools/install-python.sh builds it and copies it into python/tether
#: while the wheel is built (docs/fmu-export.md).
_EXPORT_RUNTIME = "libtether_fmu_export.so"
# The host program an exported FMU carries for its isolated members.
_HOST_PROGRAM = "tether-fmi-host"


def export_fmu(system: Union[PathLike, "System"], path: PathLike, fmi: int = 2) -> str:
    """Export ``system`` (a system file path with an ``[export]`` table, an
    SSP — ``.ssp``, ``.ssd`` or folder — whose root connectors are the
    interface unless its Tether annotation has an ``[export]`` table, or a
    :class:`System`) as one FMI 2.0 (``fmi=2``) or FMI 3.0 (``fmi=3``)
    co-simulation FMU at ``path``, as ``tether fmu export`` does, with the
    same loader (docs/fmu-export.md); returns the path. The FMU's binary is the runtime
    library shipped in this package; a system with isolated members also
    carries the package's host program."""
    folder = os.path.dirname(os.path.abspath(__file__))
    runtime, host = (os.path.join(folder, name) for name in (_EXPORT_RUNTIME, _HOST_PROGRAM))
    if not os.path.isfile(runtime):
        raise SettingsError(
            f"the FMU runtime {runtime} is not installed with the tether package "
            "(install the package with tools/install-python.sh, which builds it into the wheel)"
        )
    host = host if os.path.isfile(host) else None
    try:
        _tether.export_fmu(os.fspath(path), runtime, host=host, fmi=fmi, **_source(system))
    except _tether.Failure as f:
        raise _error(f) from None
    return os.fspath(path)


from .studies import (  # noqa: E402  (they use the classes above)
    ConvergenceCurve,
    StabilityMap,
    StudyResult,
    study,
    sweep_convergence,
    sweep_stability,
)
