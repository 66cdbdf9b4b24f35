"""The solver stages' shape (issue 63): a solver is `init`/`step`/`terminate` run by the one
shared loop (`learn.iterate`), and restarts, warm starts and keep-if-better are wrappers
(`learn.Restarts`, `learn.WarmStart`, `learn.KeepIfBetter`) around any stage. A solver of
this file's own (gradient descent, one class) runs through the loop and under each wrapper;
each wrapper is checked for what it promises."""

import dataclasses
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ToyProblem

import learn


class _Point(eqx.Module):
    w: jax.Array


class _Quadratic(learn.AbstractObjective):
    """$f(w) = \\mathrm{mean}((w - t)^2)$ over the targets `t` of the data."""

    def __call__(self, y, args):
        return jnp.mean((y.w - args) ** 2)


@dataclasses.dataclass
class _State:
    w: jax.Array
    done: int = 0


@dataclasses.dataclass(frozen=True)
class GradientDescent(learn.AbstractSolver):
    """A solver in one class: `iterations` steps of `w -= rate * grad f` (a negative rate
    climbs: a solver that makes the loss worse), stopping once the loss is below `tol`."""

    iterations: int = 10
    rate: float = 0.25
    tol: float = 0.0
    seen: ClassVar[list] = []  # the starts of the runs, in order

    def init(self, problem, context):
        GradientDescent.seen.append(problem.y0.w)
        return _State(problem.y0.w)

    def step(self, problem, state):
        grad = jax.grad(lambda w: problem.objective(_Point(w), problem.train))(state.w)
        state.w = state.w - self.rate * grad
        state.done += 1
        loss = float(problem.objective(_Point(state.w), problem.train))
        return state, learn.Step(1, np.array([state.done]), np.array([loss]), np.array([np.nan]))

    def terminate(self, problem, state, losses):
        return bool(losses) and losses[-1] < self.tol

    def current(self, state):
        return _Point(state.w)


def _problem(start=0.0, targets=(2.0,), validation=None):
    return ToyProblem(_Quadratic(), _Point(jnp.asarray(start)), jnp.asarray(targets),
                      None if validation is None else jnp.asarray(validation))


def test_a_solver_of_its_own_runs_in_the_shared_loop():
    seen = []
    context = learn.Context(report=lambda done, total, train, val: seen.append((done, total, train)), total=10)
    result = GradientDescent(10).run(_problem(), context)
    # w_k = 2 (1 - 0.5^k): the loss (w_k - 2)^2 = 4 * 0.25^k, each step a factor 4 (exact in binary)
    np.testing.assert_array_equal(result.history["train_loss"], 4.0 * 0.25 ** np.arange(1, 11))
    np.testing.assert_array_equal(result.history["epoch"], np.arange(1, 11))
    assert float(result.y.w) == 2.0 * (1 - 0.5**10)
    record = result.record
    assert record.optimiser == "GradientDescent" and record.iterations == 10 and record.kept
    assert record.train_loss == 4.0 * 0.25**10 and np.isnan(record.val_loss)
    assert record.settings == {"iterations": 10, "rate": 0.25, "tol": 0.0}
    assert [s[0] for s in seen] == list(range(1, 11)) and {s[1] for s in seen} == {10}
    # `terminate` ends the run: the loss falls below 1e-3 after 5 steps (4 * 0.25^5 = 3.9e-3, ^6 = 9.8e-4)
    short = GradientDescent(10, tol=1e-3).run(_problem(), learn.Context())
    assert short.record.iterations == 6 and short.history["train_loss"][-1] < 1e-3


def test_keep_if_better_returns_the_start_when_the_solver_makes_the_loss_worse():
    worse = GradientDescent(3, rate=-0.25)  # climbs
    problem = _problem(start=1.0)
    alone = worse.run(problem, learn.Context())
    assert float(alone.y.w) != 1.0 and alone.record.train_loss > 1.0  # the solver alone hands on its climb
    kept = learn.KeepIfBetter(worse).run(problem, learn.Context())
    assert float(kept.y.w) == 1.0 and not kept.record.kept
    assert kept.record.train_loss == 1.0 == kept.record.details["train_loss_before"]
    # a solver that lowers the loss is kept, its iterate unchanged
    better = learn.KeepIfBetter(GradientDescent(3)).run(problem, learn.Context())
    assert better.record.kept and float(better.y.w) == float(GradientDescent(3).run(problem, learn.Context()).y.w)
    # the validation loss decides where there is one: training targets 2, validation 0
    held = learn.KeepIfBetter(GradientDescent(3)).run(_problem(start=0.0, validation=(0.0,)), learn.Context())
    assert float(held.y.w) == 0.0 and not held.record.kept


def test_restarts_returns_the_best_of_its_starts():
    problem = _problem(start=5.0)
    stage = learn.Restarts(GradientDescent(1, rate=0.1), 4)
    GradientDescent.seen.clear()
    result = stage.run(problem, learn.Context(seed=3))
    # the first start is the problem's, the others fresh ones from the fit's seed
    key = jax.random.PRNGKey(3)
    starts = [5.0] + [float(problem.reinitialised(jax.random.fold_in(key, r)).w) for r in (1, 2, 3)]
    np.testing.assert_array_equal(np.asarray(GradientDescent.seen), np.asarray(starts))
    # one step of rate 0.1 from w: w - 0.2 (w - 2); the best is the start nearest the target
    ends = [w - 0.1 * 2 * (w - 2.0) for w in starts]
    best = int(np.argmin([(w - 2.0) ** 2 for w in ends]))
    assert best not in (0, 3)  # neither the problem's own start nor the last run: the choice matters
    assert result.record.details["best_start"] == best
    assert float(result.y.w) == pytest.approx(ends[best], rel=4 * np.finfo(float).eps)  # 2 roundings
    np.testing.assert_allclose(result.record.details["start_train_losses"], [(w - 2.0) ** 2 for w in ends],
                               rtol=16 * np.finfo(float).eps)  # squares of those
    assert stage.budget == 4 and stage.name == "GradientDescent"
    with pytest.raises(ValueError, match="Restarts.starts"):
        learn.Restarts(GradientDescent(), 0)


@dataclasses.dataclass(frozen=True)
class _Warm(ToyProblem):
    """A problem that offers a simpler one: targets halved, whose solution doubled starts it."""

    def warm_start(self):
        simpler = dataclasses.replace(self, train=self.train / 2, y0=_Point(jnp.asarray(-1.0)))
        return simpler, lambda y: _Point(2 * y.w)


def test_warm_start_solves_the_simpler_problem_first_and_starts_from_its_mapped_solution():
    problem = _Warm(_Quadratic(), _Point(jnp.asarray(0.0)), jnp.asarray([2.0]))
    GradientDescent.seen.clear()
    result = learn.WarmStart(GradientDescent(8, rate=0.5)).run(problem, learn.Context())
    # half the budget on the simpler problem (rate 0.5 solves a quadratic in one step: w = 1),
    # then the rest from its solution mapped on (2 * 1 = 2, the full problem's minimum)
    assert [float(w) for w in GradientDescent.seen] == [-1.0, 2.0]
    assert float(result.y.w) == 2.0 and result.record.iterations == 8
    np.testing.assert_array_equal(result.history["train_loss"], np.zeros(8))
    # a problem that offers none: the stage alone
    GradientDescent.seen.clear()
    learn.WarmStart(GradientDescent(2)).run(_problem(start=0.5), learn.Context())
    assert [float(w) for w in GradientDescent.seen] == [0.5]


def test_the_library_solvers_are_wrapped_the_same_way():
    """The paper's G-LPNet training as wrappers (no flags): its record names the solver, and the
    composition's budget is the starts' iterations."""
    stage = learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(30)), 2))
    assert stage.name == "ScipyBFGS" and stage.budget == 60 and not stage.resumable
    assert learn.KeepIfBetter(learn.LevenbergMarquardt(5)).resumable and learn.Adam(5).resumable
    problem = _problem(start=0.0, targets=(1.0, 3.0))
    for solver in (learn.ScipyBFGS(20), learn.ScipyLBFGSB(20), learn.OptaxLBFGS(200), GradientDescent(60, rate=0.5)):
        result = learn.KeepIfBetter(solver).run(problem, learn.Context())
        # the minimum of mean((w - t)^2) is the mean target, 2: reached to a few ulps
        assert result.record.kept and result.record.optimiser == type(solver).__name__
        assert float(result.y.w) == pytest.approx(2.0, rel=0, abs=1e-7), solver


def test_fit_takes_a_solver_of_its_own_wrapped(monkeypatch):
    """`learn.fit` runs any `learn.AbstractSolver` in any wrapper; its progress reports name it."""
    import integrators as it
    import liepoisson as lp

    body = lp.systems.RigidBody()
    data = it.ground_truth(body, np.array([[1.0, 0.5, 0.2]]), h=0.1, n_steps=10, progress=False)

    @dataclasses.dataclass(frozen=True)
    class Adamish(learn.AbstractSolver):
        iterations: int = 3
        unit: ClassVar[str] = "epoch"

        def init(self, problem, context):
            return [problem.y0, 0]

        def step(self, problem, state):
            state[1] += 1
            return state, learn.Step(1, np.array([state[1]]), np.array([float(problem.losses(state[0]).train)]),
                                     np.array([np.nan]))

        def current(self, state):
            return state[0]

    seen: list[Any] = []
    _, record = learn.fit(learn.GLPNet(body, n_modules=2, key=0), data, optimiser=learn.KeepIfBetter(Adamish()),
                          progress=False, callback=seen.append)
    assert [s.optimiser for s in seen] == ["Adamish"] * 4 and [s.iteration for s in seen] == [1, 2, 3, 3]
    assert record.stages[0].optimiser == "Adamish" and not record.stages[0].kept  # nothing moved: not better
