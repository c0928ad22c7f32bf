"""The learner kinds a run chooses from (registry.py: the paper's, from actors/learning, and this package's), and
policies trained elsewhere acting as a swarm's agents: learner kinds that decide but do not learn.

`onnx.py`: `[learner] kind = "onnx"`, each agent's action from an ONNX file run by onnxruntime (the `onnx` extra).
They live outside actors/learning, which imports only numpy and numba; the registry, above both, names every kind by
module path."""
