# Configuration check and the helpers every rule file uses (no rules here).
import functools
import json
import os
from pathlib import Path

from snakemake.utils import validate

from cgfem.case import load_case
from cgfem.memory import case_measures, machine_memory, run_memory


validate(config, "../schemas/config.schema.yaml")

EXAMPLES = config["examples"]
SURFACES = config["surfaces"]
RUN = "results/runs/{case}/L{level}_{surface}"
#: run folder of a higher element order (examples.*.orders; order 1 keeps RUN)
RUN_ORDER = "results/runs/{case}/L{level}_{surface}_o{order}"
#: the bodies' embeddings, built once per geometry, grid and boundary quadrature and loaded by
#: every later run and error table on them (`cgfem run --embedding-cache`): nurbs_fe and
#: nurbs_fit share theirs; the results are the same bits either way
EMBEDDINGS = "results/cache/embeddings"
#: the kernels compiled in shares before the runs (rule compile_kernels), one per core the
#: workflow may use (at most this machine's)
KERNELS = "results/cache/kernels/share_{share}_of_{shares}.json"
KERNEL_SHARES = max(1, min(int(workflow.cores or 1), os.cpu_count() or 1))
#: software of every rule (relative to the rule files)
ENV = "../envs/cgfem.yaml"


wildcard_constraints:
    case="|".join(EXAMPLES),
    level=r"\d+",
    surface="|".join(SURFACES),
    order="2",
    share=r"\d+",
    shares=r"\d+",


#: the memory (MB) the runs may hold at once: ``--resources mem_mb=N`` or, run on this
#: machine (no --jobs for a cluster), its physical memory. Every run reserves its estimate
#: (cgfem.memory.run_memory), so that two large runs (chain3 at level 3 with nurbs_fit, 15 GB,
#: and facets, 11 GB) do not start together on a 25 GB machine; on a cluster each job
#: requests its own.
def _global_resource(name):
    """The value of the workflow's resource ``name`` (snakemake 9 wraps it), None if unset."""
    value = workflow.global_resources.get(name)
    return getattr(value, "value", value)


if _global_resource("mem_mb") is None and _global_resource("_nodes") is None:
    workflow.register_resource("mem_mb", machine_memory() // 10**6)


@functools.cache
def _case(path):
    """The case file ``path`` loaded, and its bodies' boundary measures: once per file, not
    once per run (85 ms each; snakemake asks for every job's memory)."""
    case = load_case(Path(path))
    return case, case_measures(case)


@functools.cache
def _run_memory_mb(case, level, surface, order):
    loaded, measures = _case(case)
    need = run_memory(loaded, level, surface, order, measures=measures) // 10**6
    limit = _global_resource("mem_mb")
    return int(need if limit is None else min(need, limit))


def run_memory_mb(wildcards):
    """The estimated memory (MB) of the run of ``wildcards`` (its order 1 unless it names
    one), at most the budget."""
    return _run_memory_mb(case_file(wildcards), int(wildcards.level), wildcards.surface,
                          int(wildcards.get("order", 1)))


def case_file(wildcards):
    """The case file of the example ``wildcards.case``."""
    return EXAMPLES[wildcards.case]["case"]


def run_folder(wildcards):
    return RUN.format(**wildcards)


#: each run's seconds in a full run of the default configuration, one thread, by its folder
#: under results/runs (``python3 -m benchmarks.bench_pipeline --record-runs``)
RUN_SECONDS = json.loads(Path("config/run_seconds.json").read_text())
#: the priority of a run not recorded: before every recorded one
UNRECORDED = 1.0 + max(RUN_SECONDS.values(), default=0.0)
#: the priority of the jobs that go before every run (the kernels' compilation; the cases'
#: checks, which the runs need, right after)
FIRST = 10**6


def run_priority(wildcards):
    """A run job's priority: its recorded seconds, so that the cores take the longest runs
    first and finish together (longest processing time first); a run not recorded (a level
    or a case file the default configuration does not run, as the extended configuration's
    level-3 runs) before every recorded one."""
    order = wildcards.get("order")
    name = f"{wildcards.case}/L{wildcards.level}_{wildcards.surface}" + (f"_o{order}" if order else "")
    return float(RUN_SECONDS.get(name, UNRECORDED))


def summaries(case, surfaces=None, levels=None):
    """summary.json of every run of ``case`` (all configured levels and definitions, or the
    given ones)."""
    return expand(
        f"{RUN}/summary.json",
        case=case,
        level=EXAMPLES[case]["levels"] if levels is None else levels,
        surface=SURFACES if surfaces is None else surfaces,
    )


def order_runs(case, order):
    """(level, surface) of every run of ``case`` at element ``order`` (examples.*.orders)."""
    entry = EXAMPLES[case].get("orders", {}).get(order, {})
    return [(level, surface) for level in entry.get("levels", [])
            for surface in entry.get("surfaces", SURFACES)]


def order_summaries(case, order=2):
    """summary.json of every run of ``case`` at element ``order`` (none if not configured)."""
    return [f"{RUN_ORDER}/summary.json".format(case=case, level=level, surface=surface, order=order)
            for level, surface in order_runs(case, order)]


def all_summaries():
    return [path for case in EXAMPLES for path in summaries(case)]


def planar_error_tables():
    return expand(
        "results/analysis/planar/errors_L{level}_{surface}.csv",
        level=EXAMPLES["planar"]["levels"],
        surface=SURFACES,
    )


def fig10_surfaces():
    """fig10 compares facets with nurbs_fit (the paper's Fig. 10); nurbs_fe stands in when
    nurbs_fit is not among the configured surfaces."""
    return ["facets", "nurbs_fit" if "nurbs_fit" in SURFACES else "nurbs_fe"]


def fig15_summaries():
    return [
        f"results/runs/chain2_rubber/L{run['level']}_{run['surface']}/summary.json"
        for run in config["figures"]["fig15"]["runs"]
    ]


#: final products: figure name -> (PNG, PDF)
FIGURES = ["fig09", "fig10", "fig13", "fig14", "fig15", "fig17", "newton", "timings", "geometry",
           "accuracy"]
#: the chain examples of the accuracy figure and of the claims' order-2 line
CHAINS = ["chain2_steel", "chain2_rubber", "chain3"]


#: body-fitted references of the chain examples (workflow/rules/reference.smk has one rule
#: per reference), example -> the case file it solves. The validation figure and the claims'
#: distances use them only when every chain example is configured with that case file (the
#: full run); a configuration with other loads or steps (the smoke one) skips them.
REFERENCE_CASES = {c: f"config/cases/{c}.yaml" for c in ("chain2_steel", "chain2_rubber", "chain3")}
REFERENCED = all(
    c in EXAMPLES and os.path.normpath(EXAMPLES[c]["case"]) == os.path.normpath(f)
    for c, f in REFERENCE_CASES.items()
)
FIGURES += ["validation"] if REFERENCED else []


def reference_files(cases=None):
    """results/reference/{case}.json of ``cases`` (default: every chain example), or none
    when the configuration does not solve the references' cases."""
    if not REFERENCED:
        return []
    return [f"results/reference/{c}.json" for c in (cases or REFERENCE_CASES)]
