"""Meta-test (the paper's Algorithm 3): train fresh policies with a learned critic, model-free.

The simulator is built **without gradients** (``requires_grad=False``): it only produces rollouts,
and the policies follow ``-alpha * grad_theta sum_t L(s_t, pi_theta(s_t), g)`` of the saved critic.
Works for every method's run directory: our critic, and the Q functions of the baselines (DDPG,
Meta-Critic, TD3, SAC: every registered method)
(through the critic loader its method registered, e.g. :func:`~warp_critic.methods.q_networks.test_critic_from_checkpoint`, which returns a module with the same signature
``L(q, qd, tau, g)`` -- for a Q function, ``L = -Q``).

Two aggregations of the final error are reported, for every goal and init:

* ``mean`` / ``std`` / ``final_error_*``: ``||q_T - g||^2``, the squared joint-space distance summed
  over the joints (rad^2), the task loss the critic was meta-trained on;
* ``mse_*``: ``mean_j (q_T,j - g_j)^2``, the *mean* squared error over the joints (rad^2), i.e. the
  sum divided by ``dof``. The paper's Tables 1-3 report "the mean squared error between last state
  and goal"; the authors' earlier ML3 code reports its reacher error the same way,
  ``torch.mean((states[-1, :2] - goal[:2]) ** 2)``. Compare with the paper in this column.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

import warp_critic.methods  # noqa: F401  (registers every method's critic loader)
from warp_critic.learning.inner import policy_fn
from warp_critic.learning.losses import final_error
from warp_critic.learning.rollout import rollout
from warp_critic.running.files import (
    DiskFullError,
    check_output_file,
    check_recording_replaceable,
    check_replaceable,
    write_result,
)
from warp_critic.running.goals import sample_goals  # noqa: F401  (metatest.sample_goals, as before)
from warp_critic.running.metatest_setup import (  # noqa: F401  (meta-test's names, as before)
    MetaTestConfig,
    MetaTestSetup,
    build_test_critic,
    setup_meta_test,
)

RESULT_KIND = "warp-critic/metatest-v1"


def meta_test(
    tc: MetaTestConfig, progress: Callable[[str], None] | None = None, record: bool = False
) -> dict:
    """Algorithm 3 on ``G x K`` fresh policies; writes and returns the results (see the module docstring).

    ``progress`` (the CLI passes ``print``) gets the summary, one line per call; nothing is printed.
    ``record``: also write a rerun recording beside the results
    (:mod:`warp_critic.running.recording_metatest`; its path in ``result["recording"]``).
    """
    out = check_output_file(Path(tc.out) if tc.out else Path(tc.run_dir) / "metatest.json", "out")
    if record:
        from warp_critic.running.recording_metatest import metatest_recording_path

        rrd = metatest_recording_path(out)
    m = setup_meta_test(tc)
    ours = _not_anothers(out, tc, m.ckpt.get("run_id"))
    if record:  # beside the result, it replaces only that result's own recording
        check_recording_replaceable(rrd, "out", ours)
    ckpt, scene, goals, goal, sim, policy = m.ckpt, m.scene, m.goals, m.goal, m.sim, m.policy
    params, q0, qd0, steps, horizon, alpha = m.params, m.q0, m.qd0, m.steps, m.horizon, m.alpha
    G, K = goals.shape[0], m.inits
    before = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
    params, trajs = m.update(params, create_graph=False)
    after = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
    err = final_error(after.q[-1], goal).view(G, K).cpu()
    err0 = final_error(before.q[-1], goal).view(G, K).cpu()
    per_goal = err.mean(1)
    mse, mse0 = err / scene.dof, err0 / scene.dof  # mean over the joints instead of the sum
    result = {
        "kind": RESULT_KIND,
        "run_dir": str(tc.run_dir),
        "run_id": ckpt.get("run_id"),
        "method": ckpt.get("method", "ours"),
        "scene": scene.name,
        "goals": goals.tolist(),
        "goal_std": tc.goal_std if tc.goals is None else None,
        "goal_noise": tc.goal_noise if tc.goals is None else None,
        "inits": K,
        "policy_steps": steps,
        "alpha": alpha,
        "horizon": horizon,
        "variant": {
            "ee_mass": tc.ee_mass,
            "link_length": tc.link_length,
            "link_scale": tc.link_scale,
            "changes": tc.variant,
        },
        "final_error_per_goal": per_goal.tolist(),
        "final_error_all": err.tolist(),
        "mean": float(err.mean()),
        "std": float(err.std(unbiased=False)),
        "mean_before": float(err0.mean()),
        # the same, averaged over the joints instead of summed (the paper's "mean squared error")
        "mse_per_goal": mse.mean(1).tolist(),
        "mse_mean": float(mse.mean()),
        "mse_std": float(mse.std(unbiased=False)),
        "mse_mean_before": float(mse0.mean()),
    }
    if progress:
        progress(
            f"meta-test {result['method']} on {scene.name}: {G} goals x {K} inits, "
            f"{steps} policy step(s), no model gradient"
        )
        progress(
            f"  final error per goal, mean over {K} inits: ||q_T - g||^2 summed over the joints, "
            f"and its mean over the {scene.dof} joints (MSE, the paper's tables)"
        )
        for i, e in enumerate(per_goal.tolist()):
            progress(
                f"  goal {i:2d} {np.array2string(goals[i].numpy(), precision=2)}  "
                f"final sq. error {e:.4f}  MSE {e / scene.dof:.4f}"
            )
        progress(
            f"  sq. error: mean {result['mean']:.4f}  std {result['std']:.4f}  "
            f"(untrained policies: {result['mean_before']:.4f})"
        )
        progress(
            f"  MSE:       mean {result['mse_mean']:.4f}  std {result['mse_std']:.4f}  "
            f"(untrained policies: {result['mse_mean_before']:.4f})"
        )
    write_result(out, result)
    result["output"] = str(out)
    if record:
        from warp_critic.running.recording_metatest import record_meta_test

        rollouts = [before, *trajs[1:], after]  # the policies at every step
        try:
            result["recording"] = str(
                record_meta_test(rrd, sim, goals, goal, K, rollouts, result["method"])
            )
        except DiskFullError as e:  # the results are on disk: say so in the one line
            raise DiskFullError(f"{e}; the results {out} were written whole") from None
    return result


def _not_anothers(out: Path, tc: MetaTestConfig, run_id: str | None) -> bool:
    """An existing ``out`` is replaced only if it is a meta-test result of this run (the same run id,
    or, for a result without one, the same run directory): never another run's or command's
    (:func:`~warp_critic.running.files.check_replaceable`). Returns whether one is there."""

    def same(old: dict) -> str | None:
        same_dir = Path(str(old.get("run_dir"))).resolve() == Path(tc.run_dir).resolve()
        if (old.get("run_id") == run_id) if old.get("run_id") and run_id else same_dir:
            return None
        return f"of the run {old.get('run_dir')}"

    return check_replaceable(out, "out", RESULT_KIND, same)
