"""Policies trained elsewhere, acting as a swarm's agents: learner kinds that decide but do not learn.

`onnx.py`: `[learner] kind = "onnx"`, each agent's action from an ONNX file run by onnxruntime (the `onnx` extra).
They live outside actors/learning, which imports only numpy: the registry there names them by module path
(actors/learning/kinds.py)."""
