"""`[learner] kind = "onnx"`: each DOF agent acts with a frozen policy read from an ONNX file, run by onnxruntime.

The contract a policy meets (docs/env.md, "Run a policy as a swarm"), the same as parallel_env's agents see:
- input 1: the agent's observation S_i, clipped to its declared bounds, as a float tensor of shape (1, n) (float32
  or float64, as the model declares it); n is the observation's size (`parallel_env(...).observation_space(a)`);
- input 2 (optional; a file shared by every agent): the agent's index in the robot's DOF order (parallel_env's
  `possible_agents`), shape (1,) or (1, 1), an integer or a float tensor as the model declares it;
- output 1: three scores over the moves (0 one move down, 1 none, 2 one move up); the agent takes the highest among
  the moves its task allows (parallel_env's action_mask), the first of equal ones.

`policy` names one `.onnx` file (shared by every agent) or a directory holding `<agent>.onnx` for each DOF agent.
Every file is opened and tried on its agent's observation before anything is spawned (`check`): a missing
file, a file that is no ONNX model, an input of another size, other than three scores or a non-finite score is
refused in one line. A non-finite score at run time (an input the check did not try) makes the agent keep still at
that step, and says so once on its log (stderr): the swarm goes on; the agent's log names the step.

Deterministic: the same observation gives the same action in every placement, the env and the swarm alike.
"""

from __future__ import annotations

import sys
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.learning.settings import N_ACTIONS, LearnerSettings

INSTALL = "pip install 'kinswarm[onnx]'"


class PolicyError(ValueError):
    """A policy this run cannot use: the message names the file and what is wrong."""


def _runtime() -> Any:
    try:
        import onnxruntime
    except ImportError:
        raise PolicyError(f'kind "onnx" runs policies with onnxruntime, which is not installed: {INSTALL}') from None
    return onnxruntime


def policy_file(policy: object, agent: str) -> Path:
    """The file `agent` acts from: `policy` itself, or `<agent>.onnx` in the directory it names."""
    if not isinstance(policy, str) or not policy:
        raise PolicyError(f"expected the path of an .onnx file or of a directory of <agent>.onnx files, got {policy!r}")
    path = Path(policy)
    if path.is_dir():
        path = path / f"{agent}.onnx"
        if not path.is_file():
            raise PolicyError(f"{policy}: no {agent}.onnx in the directory (one file per agent with a joint)")
    elif not path.is_file():
        raise PolicyError(f"{policy}: no such file or directory")
    return path


class OnnxPolicy:
    """One agent's frozen policy (the JointLearner protocol, actors/learning/kinds.py): it decides, it never learns.

    `bounds`: the observation's (lo, hi) per variable, which S_i is clipped to as parallel_env clips it."""

    n_actions = N_ACTIONS

    def __init__(self, path: Path, bounds: Sequence[tuple[float, float]], index: int) -> None:
        ort = _runtime()
        self.path, self.index = path, index
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1  # one agent, one core: its process's
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own kinds for a bad file: its first line says what
            raise PolicyError(f"{path}: not a model onnxruntime can run ({_first_line(e)})") from None
        self._lo = np.array([lo for lo, _ in bounds], dtype=np.float64)
        self._hi = np.array([hi for _, hi in bounds], dtype=np.float64)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) not in (1, 2):
            n = len(inputs)
            raise PolicyError(f"{path}: expected 1 input (the observation) or 2 (and the agent's index), has {n}")
        obs = inputs[0]
        self._obs_name, self._obs_type = obs.name, _dtype(path, obs)
        size = obs.shape[-1] if obs.shape else None
        if not obs.shape or len(obs.shape) != 2 or (isinstance(size, int) and size != len(bounds)):
            raise PolicyError(
                f"{path}: input {obs.name!r} has shape {obs.shape}; this agent's observation is (1, {len(bounds)})"
            )
        self._index: dict[str, np.ndarray] = {}
        if len(inputs) == 2:
            ix = inputs[1]
            shape = (1,) if len(ix.shape or [1]) == 1 else (1, 1)
            self._index = {ix.name: np.full(shape, index, dtype=_dtype(path, ix))}
        self._out = outputs[0].name
        self._warned = False
        self.steps = 0
        scores = self.scores((self._lo + self._hi) / 2)  # tried once now: a bad model is refused before a run
        if scores.size != N_ACTIONS:
            raise PolicyError(f"{path}: gives {scores.size} scores; expected {N_ACTIONS} (one move down, none, up)")
        if not np.all(np.isfinite(scores)):
            raise PolicyError(f"{path}: gives a non-finite score {scores.tolist()} at the middle of the observation")

    def scores(self, state: np.ndarray) -> np.ndarray:
        s = np.clip(np.asarray(state, dtype=np.float64), self._lo, self._hi)
        feed = {self._obs_name: s.astype(self._obs_type).reshape(1, -1), **self._index}
        try:
            out = self.session.run([self._out], feed)[0]
        except Exception as e:  # a model whose shapes do not fit this input fails at run: its first line says what
            raise PolicyError(f"{self.path}: cannot run on this agent's observation ({_first_line(e)})") from None
        return np.asarray(out, dtype=np.float64).reshape(-1)

    # -- the JointLearner protocol -------------------------------------------------------------------
    def decide(
        self,
        state: np.ndarray,
        reward: float | None,
        learn: bool = True,
        explore: bool = True,
        avoid: Collection[int] = (),
    ) -> int:
        self.steps += 1
        scores = self.scores(state)
        if not np.all(np.isfinite(scores)):
            if not self._warned:
                self._warned = True
                print(
                    f"{self.path}: a non-finite score {scores.tolist()} at decision {self.steps}: kept still "
                    "(said once)",
                    file=sys.stderr,
                    flush=True,
                )
            return 1
        allowed = np.ones(N_ACTIONS, dtype=bool)
        allowed[[a for a in avoid if 0 <= a < N_ACTIONS]] = False
        return int(np.argmax(np.where(allowed, scores, -np.inf)))

    def observe(self, visible_actions: Sequence[int], learn: bool = True) -> None:
        pass  # a policy models no children

    def start_epoch(self, epoch: int, t: int = 0) -> None:
        pass

    def resync(self, t: int) -> None:
        pass

    def state_dict(self) -> dict[str, np.ndarray]:
        return {}  # nothing learned: a checkpoint holds no arrays, the file is the policy

    def load_state_dict(self, d: dict[str, np.ndarray]) -> None:
        if d:
            raise ValueError(f"an ONNX policy learns nothing; a checkpoint of {', '.join(sorted(d))} does not fit it")


def _first_line(e: Exception) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


def _dtype(path: Path, arg: Any) -> type:
    kinds = {
        "tensor(float)": np.float32,
        "tensor(double)": np.float64,
        "tensor(int64)": np.int64,
        "tensor(int32)": np.int32,
    }
    if arg.type not in kinds:
        raise PolicyError(f"{path}: input {arg.name!r} is a {arg.type}; expected a float or an integer tensor")
    return kinds[arg.type]


def build(
    settings: LearnerSettings,
    n_visible: int,
    seed: int | Sequence[int],
    *,
    agent: str,
    index: int,
    options: Mapping[str, Any],
) -> OnnxPolicy:
    """The kind's builder (actors/policies/registry.py): the agent's file, its observation's bounds, its index."""
    return OnnxPolicy(policy_file(options.get("policy"), agent), settings.observation.bounds, index)


def check(settings: Mapping[str, LearnerSettings], order: Sequence[str], options: Mapping[str, Any]) -> None:
    """Every DOF agent's policy opened and tried (`order`: the DOF agents, whose place is the index input)."""
    if "policy" not in options:
        raise PolicyError(
            'kind "onnx" needs `policy`: an .onnx file shared by every agent, or a directory of <agent>.onnx files'
        )
    for i, agent in enumerate(order):
        build(settings[agent], 0, 0, agent=agent, index=i, options=options)
