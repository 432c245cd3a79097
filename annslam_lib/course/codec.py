"""Data, never code, between the grader and the kernel that runs a student's functions.

The grader decides scores in its own process (:mod:`annslam_lib.course.grader`); a student's
function runs in a sandboxed kernel, and only its arguments and its return value cross
between the two, encoded here as JSON. Nothing is pickled: a value that is not one of the
types below arrives as an :class:`Opaque` (its type name and a shortened repr), which no
check accepts as an answer.

Encoded types: None, bool, int, float, complex, str; tuple, list, dict with str keys;
NumPy arrays and scalars of bool, integer, float or complex dtype (base64 of ``np.save``
with ``allow_pickle=False``); torch tensors; torch ``nn.Sequential`` stacks of Linear, Tanh,
ReLU, Sigmoid and Identity layers (their structure and weights) and the SGD and Adam
optimizers over one module's parameters (their hyper-parameters), which is what the
chapter 07 training-loop exercise passes; the course's :class:`~annslam_lib.models.vehicle.
Vehicle` (its four lengths: the capstone's probes pass one); SciPy sparse matrices, sent in
compressed-row form (their data, indices, row pointers and shape; checked in full when
rebuilt: chapter 11's Gauss-Newton step is passed one); exceptions (class names along
the MRO, module, message). Sizes are bounded (:data:`MAX_BYTES`).
"""
from __future__ import annotations

import base64
import io
import json
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MAX_BYTES", "MAX_LAYERS", "MAX_SPARSE_CELLS", "CodecError", "Opaque", "RemoteException", "encode", "decode",
           "dumps", "loads"]

#: Largest encoded message accepted (a student's function returning a huge array is refused
#: before it is parsed).
MAX_BYTES = 64 << 20
#: Most layers an encoded torch module may list.
MAX_LAYERS = 64
_DTYPE_KINDS = "biufc"
_LAYERS = ("Linear", "Tanh", "ReLU", "Sigmoid", "Identity")
_OPTIMIZERS = ("SGD", "Adam")


class CodecError(ValueError):
    """A value cannot be encoded, or a message is malformed or too large."""


@dataclass(frozen=True)
class Opaque:
    """A value of a type the codec does not carry: only its type name and a short repr."""
    type_name: str
    text: str

    def __repr__(self) -> str:
        return self.text

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True)
class RemoteException:
    """An exception raised in the kernel: its class names along the MRO (most derived
    first), the defining module of the first, and its message."""
    names: tuple[str, ...]
    module: str
    message: str


def _array(a: np.ndarray) -> dict:
    if a.dtype.kind not in _DTYPE_KINDS:
        raise CodecError(f"array of dtype {a.dtype} cannot be sent")
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return {"t": "nd", "b": base64.b64encode(buf.getvalue()).decode("ascii")}


def _torch():
    import torch
    return torch


def module_spec(m) -> dict:
    torch = _torch()
    if not isinstance(m, torch.nn.Sequential):
        raise CodecError(f"torch module {type(m).__name__} cannot be sent (only nn.Sequential)")
    layers = []
    for layer in m:
        kind = type(layer).__name__
        if kind not in _LAYERS or type(layer).__module__.split(".")[0] != "torch":
            raise CodecError(f"layer {kind} cannot be sent")
        if kind == "Linear":
            layers.append([kind, layer.in_features, layer.out_features, layer.bias is not None])
        else:
            layers.append([kind])
    dtype = str(next(m.parameters()).dtype).removeprefix("torch.") if any(
        True for _ in m.parameters()) else "float32"
    state = {k: encode(v.detach().cpu().numpy()) for k, v in m.state_dict().items()}
    return {"t": "module", "layers": layers, "dtype": dtype, "state": state}


def build_module(spec: dict):
    """The torch ``nn.Sequential`` described by an encoded module. Its structure is checked
    against the weights sent before anything is built, so that what is allocated is what
    the message carried (a tiny message naming a huge layer builds nothing)."""
    torch = _torch()
    items, state = spec.get("layers"), spec.get("state")
    if not isinstance(items, list) or not isinstance(state, dict) or len(items) > MAX_LAYERS:
        raise CodecError(f"a module is a list of at most {MAX_LAYERS} layers with its weights")
    shapes: dict[str, tuple] = {}
    for i, item in enumerate(items):
        if not isinstance(item, list) or not item or item[0] not in _LAYERS:
            raise CodecError(f"unknown layer {item!r:.60}")
        if item[0] == "Linear":
            if len(item) != 4 or not all(type(n) is int and n > 0 for n in item[1:3]):
                raise CodecError(f"layer {i}: a Linear layer needs two positive sizes")
            shapes[f"{i}.weight"] = (item[2], item[1])
            if item[3]:
                shapes[f"{i}.bias"] = (item[2],)
    if set(state) != set(shapes):
        raise CodecError(f"module weights {sorted(state)[:8]} do not match its layers "
                         f"{sorted(shapes)[:8]}")
    weights = {k: decode(state[k]) for k in shapes}
    for k, w in weights.items():
        if not isinstance(w, np.ndarray) or w.shape != shapes[k]:
            raise CodecError(f"weight {k!r} has the wrong shape")
    dtype = spec.get("dtype", "float32")
    if dtype not in ("float32", "float64"):
        raise CodecError(f"module dtype {dtype!r} cannot be built")
    layers = [torch.nn.Linear(item[1], item[2], bias=bool(item[3]), device="meta")
              if item[0] == "Linear" else getattr(torch.nn, item[0])() for item in items]
    m = torch.nn.Sequential(*layers).to_empty(device="cpu").to(getattr(torch, dtype))
    with torch.no_grad():
        for k, v in m.state_dict().items():
            v.copy_(torch.from_numpy(np.array(weights[k])))
    return m


def load_state(module, state: dict) -> None:
    """Copy encoded weights into ``module`` in place (names and shapes must match)."""
    torch = _torch()
    own = module.state_dict()
    if set(own) != set(state):
        raise CodecError(f"module weights {sorted(state)} do not match {sorted(own)}")
    with torch.no_grad():
        for k, v in own.items():
            arr = decode(state[k])
            if not isinstance(arr, np.ndarray) or arr.shape != tuple(v.shape):
                raise CodecError(f"weight {k!r} has the wrong shape")
            v.copy_(torch.from_numpy(np.array(arr)))


def _optimizer_spec(opt, modules: list) -> dict:
    torch = _torch()
    kind = type(opt).__name__
    if kind not in _OPTIMIZERS or not isinstance(opt, torch.optim.Optimizer):
        raise CodecError(f"optimizer {kind} cannot be sent (only {', '.join(_OPTIMIZERS)})")
    if len(opt.param_groups) != 1:
        raise CodecError("only an optimizer with one parameter group can be sent")
    group = opt.param_groups[0]
    params = group["params"]
    for i, m in enumerate(modules):
        if [id(p) for p in m.parameters()] == [id(p) for p in params]:
            hyper = {k: v for k, v in group.items() if k != "params"
                     and isinstance(v, (bool, int, float, tuple, type(None)))}
            return {"t": "optim", "kind": kind, "module": i, "hyper": encode(hyper)}
    raise CodecError("an optimizer can be sent only with the module whose parameters it holds")


def build_optimizer(spec: dict, modules: list):
    torch = _torch()
    kind = spec["kind"]
    if kind not in _OPTIMIZERS:
        raise CodecError(f"unknown optimizer {kind!r}")
    hyper = decode(spec["hyper"])
    allowed = {"SGD": ("lr", "momentum", "dampening", "weight_decay", "nesterov"),
               "Adam": ("lr", "betas", "eps", "weight_decay", "amsgrad")}[kind]
    kwargs = {k: hyper[k] for k in allowed if k in hyper}
    return getattr(torch.optim, kind)(modules[int(spec["module"])].parameters(), **kwargs)


#: Most entries (rows x columns) a decoded sparse matrix may stand for.
MAX_SPARSE_CELLS = 10**8


def _csr(tree: dict):
    """A compressed-row sparse matrix from its parts, each checked here before SciPy sees
    them (SciPy's own full check skips a matrix whose last row pointer is <= 0, and such a
    matrix crashes its C code): row pointers from 0, non-decreasing, ending at the number
    of entries; column indices inside the shape; at most :data:`MAX_SPARSE_CELLS` cells;
    float64 data and int64 indices; duplicates summed."""
    import scipy.sparse as sp

    shape = tree.get("shape")
    if not (isinstance(shape, list) and len(shape) == 2 and all(
            isinstance(n, int) and not isinstance(n, bool) and 0 <= n < 2**31 for n in shape)):
        raise CodecError("malformed sparse matrix shape")
    rows, cols = shape
    if rows * cols > MAX_SPARSE_CELLS:
        raise CodecError(f"sparse matrix of {rows} x {cols} refused (more than "
                         f"{MAX_SPARSE_CELLS} cells)")
    data, indices, indptr = (decode(tree.get(k)) for k in ("data", "indices", "indptr"))
    if not all(isinstance(a, np.ndarray) and a.ndim == 1 for a in (data, indices, indptr)) or \
            indices.dtype.kind not in "iu" or indptr.dtype.kind not in "iu" or \
            data.dtype.kind not in "biuf":
        raise CodecError("malformed sparse matrix")
    if indptr.dtype == np.uint64 and indptr.size and indptr.max() >= 2**63 or \
            indices.dtype == np.uint64 and indices.size and indices.max() >= 2**63:
        raise CodecError("malformed sparse matrix: an index beyond int64")
    ip, ix = indptr.astype(np.int64), indices.astype(np.int64)
    if ip.size != rows + 1 or ip[0] != 0 or np.any(np.diff(ip) < 0) or ip[-1] != data.size \
            or ix.size != data.size or (ix.size and (ix.min() < 0 or ix.max() >= cols)):
        raise CodecError("malformed sparse matrix: its row pointers or column indices do not "
                         "fit its shape")
    m = sp.csr_matrix((data.astype(np.float64), ix, ip), shape=(rows, cols))
    m.sum_duplicates()
    return m


def encode(value, _modules: list | None = None):
    """A JSON-ready tree for ``value`` (see the module docstring); :class:`Opaque` for
    anything else. ``_modules`` collects torch modules so an optimizer can refer to one."""
    modules = [] if _modules is None else _modules
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int) and not isinstance(value, bool):
        return {"t": "int", "v": str(value)}
    if isinstance(value, float):
        return value if math.isfinite(value) else {"t": "float", "v": repr(value)}
    if isinstance(value, complex):
        return {"t": "complex", "v": [value.real, value.imag]}
    if isinstance(value, np.ndarray):
        return _array(value)
    if isinstance(value, np.generic):
        if value.dtype.kind in _DTYPE_KINDS:
            return {"t": "np", "v": _array(np.asarray(value))}
        return {"t": "opaque", "type": type(value).__name__, "text": repr(value)[:200]}
    if isinstance(value, (tuple, list)):
        return {"t": "tuple" if isinstance(value, tuple) else "list",
                "v": [encode(v, modules) for v in value]}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            return {"t": "opaque", "type": "dict", "text": repr(value)[:200]}
        return {"t": "dict", "v": {k: encode(v, modules) for k, v in value.items()}}
    if isinstance(value, BaseException):
        mro = tuple(c.__name__ for c in type(value).__mro__ if c is not object)
        return {"t": "exc", "names": list(mro), "module": type(value).__module__,
                "msg": str(value)[:2000]}
    if type(value).__name__ == "Vehicle" and type(value).__module__ == "annslam_lib.models.vehicle":
        return {"t": "vehicle", "v": {k: float(getattr(value, k)) for k in ("L", "H", "a", "b")}}
    mod = type(value).__module__.split(".")[0]
    if mod == "scipy":
        import scipy.sparse as sp

        if sp.issparse(value):
            m = sp.csr_matrix(value)
            return {"t": "csr", "data": _array(m.data), "indices": _array(m.indices),
                    "indptr": _array(m.indptr), "shape": [int(n) for n in m.shape]}
    if mod == "torch":
        torch = _torch()
        if isinstance(value, torch.Tensor):
            return {"t": "tensor", "v": _array(value.detach().cpu().numpy()),
                    "grad": value.requires_grad}
        if isinstance(value, torch.nn.Module):
            modules.append(value)
            return module_spec(value)
        if isinstance(value, torch.optim.Optimizer):
            return _optimizer_spec(value, modules)
    text = repr(value)
    return {"t": "opaque", "type": type(value).__name__, "text": text[:200]}


def decode(tree, _modules: list | None = None):
    """The value of an encoded tree (torch objects are rebuilt; others as encoded)."""
    modules = [] if _modules is None else _modules
    if tree is None or isinstance(tree, (bool, str, float)):
        return tree
    if isinstance(tree, int):
        return tree
    if not isinstance(tree, dict) or "t" not in tree:
        raise CodecError("malformed message")
    t = tree["t"]
    if t == "int":
        return int(tree["v"])
    if t == "float":
        return float(tree["v"])
    if t == "complex":
        return complex(*tree["v"])
    if t == "nd":
        a = np.load(io.BytesIO(base64.b64decode(tree["b"])), allow_pickle=False)
        if a.dtype.kind not in _DTYPE_KINDS:
            raise CodecError(f"array of dtype {a.dtype} refused")
        return a
    if t == "np":
        return decode(tree["v"])[()]
    if t in ("tuple", "list"):
        items = [decode(v, modules) for v in tree["v"]]
        return tuple(items) if t == "tuple" else items
    if t == "dict":
        return {str(k): decode(v, modules) for k, v in tree["v"].items()}
    if t == "exc":
        return RemoteException(tuple(str(n) for n in tree["names"]), str(tree["module"]),
                               str(tree["msg"]))
    if t == "opaque":
        return Opaque(str(tree["type"]), str(tree["text"]))
    if t == "vehicle":
        from ..models.vehicle import Vehicle
        v = tree.get("v")
        if not isinstance(v, dict) or set(v) != {"L", "H", "a", "b"} or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v.values()):
            raise CodecError("malformed vehicle")
        try:
            return Vehicle(**{k: float(x) for k, x in v.items()})
        except (TypeError, ValueError) as e:
            raise CodecError(f"malformed vehicle: {e}") from None
    if t == "csr":
        return _csr(tree)
    if t == "tensor":
        torch = _torch()
        x = torch.from_numpy(np.array(decode(tree["v"])))
        return x.requires_grad_() if tree.get("grad") and x.is_floating_point() else x
    if t == "module":
        m = build_module(tree)
        modules.append(m)
        return m
    if t == "optim":
        return build_optimizer(tree, modules)
    raise CodecError(f"unknown value type {t!r}")


def dumps(value) -> str:
    text = json.dumps(encode(value), allow_nan=False, separators=(",", ":"))
    if len(text) > MAX_BYTES:
        raise CodecError(f"message of {len(text)} bytes exceeds {MAX_BYTES}")
    return text


def loads(text: str):
    if not isinstance(text, str) or len(text) > MAX_BYTES:
        raise CodecError("message missing or too large")
    try:
        tree = json.loads(text)
    except ValueError as e:
        raise CodecError(f"malformed message: {e}") from None
    return decode(tree)
