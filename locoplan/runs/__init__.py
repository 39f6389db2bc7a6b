"""Runs as data and many of them at once: specs, records, executors, the result store, study files.

``run_many(specs, executor)`` (many.py) is the one loop behind ``study``, ``sweep``, ``compare``,
``batch`` and the benchmarks; ``Store`` (store.py) keeps finished runs so a batch resumes; ``load_study``
(study.py) turns a study file into specs; ``pareto`` (pareto.py) the energy-time front.
"""

from .executors import EXECUTORS, DaskExecutor, ProcessExecutor, SerialExecutor, make_executor
from .many import Batch, ProgressEvent, run_many
from .spec import RunRecord, RunSpec
from .store import Store

__all__ = ["RunSpec", "RunRecord", "run_many", "Batch", "ProgressEvent", "Store", "EXECUTORS", "SerialExecutor",
           "ProcessExecutor", "DaskExecutor", "make_executor"]
