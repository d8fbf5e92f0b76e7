"""Policy files (docs/training.md, "Policy files"): an MLP with its observation normalisation
as one ONNX graph (policy_onnx.write_mlp_policy), with the metadata `mjskill eval --policy`
reads and what the trainers add, replaced whole when rewritten."""

from __future__ import annotations

import os

from policy_onnx import floor_actions, write_mlp_policy
from training.files import atomic_write


def metadata(env_id, robot, mode, command, algorithm, env_steps, eval_success, version,
             hidden_obs=(), resumes=(), resume_commands=(), **extra):
    """A policy file's metadata_props: the required keys, the trainer's (``algorithm``,
    ``env_steps``, ``eval_success``, ``mjskill_version``, ``hidden_obs``), ``resumed`` and
    ``resume_commands`` for a resumed run, and ``extra`` (str values) as given."""
    meta = {
        "env_id": env_id,
        "robot_uids": robot,
        "control_mode": mode,
        "obs_mode": "state",
        "training_command": command,
        "algorithm": algorithm,
        "env_steps": str(env_steps),
        "eval_success": "" if eval_success is None else f"{eval_success:.4f}",
        "mjskill_version": version,
        "hidden_obs": ",".join(str(i) for i in hidden_obs),
    }
    meta.update({k: str(v) for k, v in extra.items()})
    if resumes:
        meta["resumed"] = ",".join(str(s) for s in resumes)
        meta["resume_commands"] = " ; ".join(resume_commands)
    return meta


def save_policy(out, tag, layers, obs_mean, obs_std, meta, obs_clip=None, floors=None,
                floor_note=None, residual=None):
    """Writes ``out/<tag>.onnx`` (replaced whole): the MLP ``layers`` (a list of (W [in, out],
    b [out])) after ``(obs - obs_mean) / obs_std`` (clipped to ±obs_clip unless None), plus
    ``residual`` (policy_onnx.write_mlp_policy: raw observation entries added to action
    entries), floored by ``floors`` ({action index: least value}, recorded with
    ``floor_note``). Returns the path."""
    path = os.path.join(out, f"{tag}.onnx")

    def write(tmp):
        write_mlp_policy(tmp, layers, obs_mean, obs_std, meta, obs_clip=obs_clip,
                         residual=residual)
        if floors:
            floor_actions(tmp, tmp, floors, floor_note)

    atomic_write(path, write)
    return path
