"""Selectable closed-loop strategies: ours (``rendezvous``, the default) and the seed's as written (``seed``).

Both take the same arguments and return the same :class:`stressbots.control.AssemblyResult`, and both
talk to the robots only through the :class:`stressbots.control.Plant` protocol:

- ``rendezvous``: :func:`stressbots.control.assemble`, the project's controller (G_1 as an orbit
  rendezvous, approach funnels, recovery from H);
- ``seed``: :func:`stressbots.seed_strategy.assemble_seed`, the seed's two-step EDR strategy (App. 3) as
  the paper describes it, for comparison (it ends in H where ours recovers).

:func:`assemble_with` is a module-level function taking the strategy *name*, so it pickles into worker
processes (Monte Carlo pools, Dask) as it is.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from .control import assemble
from .errors import StressbotsError
from .seed_strategy import assemble_seed

__all__ = ["STRATEGIES", "DEFAULT_STRATEGY", "STRATEGY_HELP", "assemble_strategy", "assemble_with", "strategy_function"]

STRATEGIES: dict[str, Callable] = {"rendezvous": assemble, "seed": assemble_seed}
"""Strategy name -> assembly function ``f(scenario, plant, *, seed, plan, time_budget_s, options)``."""

DEFAULT_STRATEGY = "rendezvous"

STRATEGY_HELP = (
    "Closed-loop strategy: 'rendezvous' (default, ours: G_1 as an orbit rendezvous, approach funnels, "
    "recovery from H) or 'seed' (the paper's two-step EDR strategy as written: sigma_1 re-planned every t_x into "
    "A_i outside C_O, S_2f/S_3f fine motion by eq. (1), G_1 in two stages; it stops in H)."
)


_HOMES = {"rendezvous": ("stressbots.control", "assemble"), "seed": ("stressbots.seed_strategy", "assemble_seed")}
"""Where each strategy's function lives: looked up at call time, so a replaced ``control.assemble`` (tests,
the control package) is the one that runs."""


def strategy_function(strategy: str) -> Callable:
    """The assembly function of ``strategy``; a :class:`StressbotsError` naming the choices otherwise."""
    if str(strategy) not in STRATEGIES:
        raise StressbotsError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}", field="strategy")
    module, name = _HOMES[str(strategy)]
    return getattr(importlib.import_module(module), name)


def assemble_with(strategy: str, scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None, options=None):
    """Assemble ``scenario`` through ``plant`` with the named strategy (see :data:`STRATEGIES`)."""
    return strategy_function(strategy)(scenario, plant, seed=seed, plan=plan, time_budget_s=time_budget_s, options=options)


def assemble_strategy(scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None, options=None,
                      strategy: str = DEFAULT_STRATEGY):
    """:func:`stressbots.control.assemble`'s signature plus ``strategy=``: the controller Monte Carlo runs
    and studies use, so a campaign (or one cell of a study) can choose the strategy by name."""
    return assemble_with(strategy, scenario, plant, seed=seed, plan=plan, time_budget_s=time_budget_s, options=options)
