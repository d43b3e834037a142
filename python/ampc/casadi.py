"""``from_casadi``: a CasADi SX function as the problem file's ``[system]`` text.

A CasADi ``Function`` f(x, u[, p]) → ẋ (``kind="ode"``) or x⁺ (``kind="discrete"``), for
example a do-mpc model's right-hand side, is read instruction by instruction
(``f.n_instructions()``, ``f.instruction_id/input/output/constant``) and written in the
problem file's expression syntax (``docs/problem-file.md``): each instruction becomes an
expression over the states, inputs and parameters by name; a value used more than once
becomes a ``definitions`` entry (computed once, as CasADi computes it once). An operation
the expression language has no form for raises :class:`ampc.AmpcError` naming it
(``OP_FLOOR``, ``OP_IF_ELSE_ZERO``, …).

Pure Python; casadi is imported only when this function is called.
"""

from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from ._ampc import AmpcError

__all__ = ["from_casadi"]

# The expression language's function names and constant (a state may not be called so).
_RESERVED = {
    "pi", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log", "sqrt",
    "sinh", "cosh", "tanh", "abs", "min", "max",
}

# CasADi operation → (arity, template). Templates take the operands already wrapped as atoms.
_UNARY = {
    "OP_NEG": "-{0}",
    "OP_EXP": "exp({0})",
    "OP_LOG": "log({0})",
    "OP_SQRT": "sqrt({0})",
    "OP_SQ": "{0}^2",
    "OP_TWICE": "2*{0}",
    "OP_INV": "1/{0}",
    "OP_SIN": "sin({0})",
    "OP_COS": "cos({0})",
    "OP_TAN": "tan({0})",
    "OP_ASIN": "asin({0})",
    "OP_ACOS": "acos({0})",
    "OP_ATAN": "atan({0})",
    "OP_SINH": "sinh({0})",
    "OP_COSH": "cosh({0})",
    "OP_TANH": "tanh({0})",
    "OP_FABS": "abs({0})",
}
_BINARY = {
    "OP_ADD": "{0} + {1}",
    "OP_SUB": "{0} - {1}",
    "OP_MUL": "{0}*{1}",
    "OP_DIV": "{0}/{1}",
    "OP_POW": "{0}^{1}",
    "OP_CONSTPOW": "{0}^{1}",
    "OP_ATAN2": "atan2({0}, {1})",
    "OP_FMIN": "min({0}, {1})",
    "OP_FMAX": "max({0}, {1})",
}
# Templates whose result is a function call or a power of atoms: no parentheses needed
# when used as an operand.
_ATOMIC = {"OP_EXP", "OP_LOG", "OP_SQRT", "OP_SIN", "OP_COS", "OP_TAN", "OP_ASIN",
           "OP_ACOS", "OP_ATAN", "OP_SINH", "OP_COSH", "OP_TANH", "OP_FABS", "OP_ATAN2",
           "OP_FMIN", "OP_FMAX"}

_Names = Union[Sequence[str], Any]


def _identifier(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name) or "v"
    if s[0].isdigit():
        s = "_" + s
    if s in _RESERVED:
        s += "_"
    return s


def _names(arg: _Names, n: int, what: str) -> List[str]:
    """Names of the n entries of an input: a list of strings, or CasADi symbols (an SX
    vector, a do-mpc/casadi struct with ``.cat``) whose scalar entries carry names."""
    if arg is None:
        raise AmpcError(f"from_casadi: {what} needs names (a list of {n} names or the SX symbols)")
    if hasattr(arg, "cat"):
        arg = arg.cat
    if isinstance(arg, (list, tuple)) and all(isinstance(a, str) for a in arg):
        names = list(arg)
    else:
        try:
            names = [arg[i].name() for i in range(arg.numel())]
        except Exception as e:  # not symbols: say what was expected
            raise AmpcError(
                f"from_casadi: {what}: expected a list of names or CasADi SX symbols, got "
                f"{type(arg).__name__} ({e})"
            ) from None
    if len(names) != n:
        raise AmpcError(f"from_casadi: {what} has {len(names)} names but the function's input has {n} entries")
    return [_identifier(s) for s in names]


def _number(v: float, where: str) -> str:
    if not math.isfinite(v):
        raise AmpcError(f"from_casadi: {where}: the constant {v} is not finite (the problem file's expressions take finite numbers)")
    s = repr(float(v))
    return f"({s})" if s.startswith("-") else s


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _toml_list(items: Sequence[str]) -> str:
    return "[" + ", ".join(_toml_str(s) for s in items) + "]"


def from_casadi(
    f: Any,
    x: _Names,
    u: _Names,
    p: Optional[Mapping[str, float]] = None,
    *,
    kind: str = "ode",
    units: Optional[Mapping[str, str]] = None,
    definition_prefix: str = "w",
) -> str:
    """The ``[system]`` section of a problem file for the CasADi function ``f``.

    ``f``: a ``casadi.Function`` with inputs (x, u) or (x, u, p) and one output of nx
    entries — ẋ = f(x, u, p) for ``kind="ode"`` (discretised by RK4 with ``ocp.ts`` and
    ``ocp.rk4_substeps``), x⁺ for ``kind="discrete"``. An MX function is expanded to SX.
    ``x``, ``u``: the names of the states and inputs, as lists or as the SX symbols (a
    do-mpc model's ``model.x``, ``model.u``). ``p``: the parameters' names and values, in
    the order of f's third input (the problem file's ``parameters`` are constants).
    ``units``: optional units by name. ``definition_prefix``: the names of shared
    intermediate values (``w1``, ``w2``, …).

    Raises :class:`ampc.AmpcError` naming an operation the expression language lacks.
    """
    import casadi as ca

    if kind not in ("ode", "discrete"):
        raise AmpcError(f'from_casadi: kind = {kind!r}: one of "ode", "discrete"')
    if not isinstance(f, ca.Function):
        raise AmpcError(f"from_casadi: f must be a casadi.Function, got {type(f).__name__}")
    if not f.is_a("SXFunction"):
        try:
            f = f.expand()
        except Exception as e:
            raise AmpcError(f"from_casadi: {f.name()} cannot be expanded to an SX function: {e}") from None
    n_in = f.n_in()
    if n_in not in (2, 3) or f.n_out() != 1:
        raise AmpcError(
            f"from_casadi: {f.name()} has {n_in} inputs and {f.n_out()} outputs; expected "
            "inputs (x, u) or (x, u, p) and one output"
        )
    nx, nu = f.numel_in(0), f.numel_in(1)
    names = [_names(x, nx, "x"), _names(u, nu, "u")]
    params: Dict[str, float] = {}
    if n_in == 3:
        np_ = f.numel_in(2)
        if p is None or len(p) != np_:
            raise AmpcError(
                f"from_casadi: {f.name()}'s third input has {np_} parameters: pass p as a "
                f"dict of {np_} names and values, in its order"
            )
        pnames = [_identifier(k) for k in p]
        params = {n: float(v) for n, v in zip(pnames, p.values())}
        names.append(pnames)
    elif p:
        raise AmpcError(f"from_casadi: p given, but {f.name()} has no third input")
    if f.numel_out(0) != nx:
        raise AmpcError(f"from_casadi: {f.name()}'s output has {f.numel_out(0)} entries, not nx = {nx}")
    used = [n for group in names for n in group]
    dup = sorted({n for n in used if used.count(n) > 1})
    if dup:
        raise AmpcError(f"from_casadi: the names {dup} appear twice among the states, inputs and parameters")

    defs, rhs = _walk(ca, f, names, nx, definition_prefix, set(used))
    lines = [
        "[system]",
        f'kind = "{kind}"',
        f"states = {_toml_list(names[0])}",
        f"inputs = {_toml_list(names[1])}",
    ]
    if params:
        lines.append(
            "parameters = { "
            + ", ".join(f"{k} = {_number(v, 'p[' + k + ']').strip('()')}" for k, v in params.items())
            + " }"
        )
    if defs:
        lines.append("definitions = [")
        lines += [f"  {_toml_str(d)}," for d in defs]
        lines.append("]")
    lines.append(("rhs" if kind == "ode" else "next") + " = [")
    lines += [f"  {_toml_str(r)}," for r in rhs]
    lines.append("]")
    if units:
        lines.append("units = { " + ", ".join(f"{_identifier(k)} = {_toml_str(v)}" for k, v in units.items()) + " }")
    return "\n".join(lines) + "\n"


def _walk(ca: Any, f: Any, names: List[List[str]], nx: int, prefix: str,
          taken: set) -> Tuple[List[str], List[str]]:
    """Expressions of f's outputs: SSA over CasADi's work vector, values used more than
    once as definitions."""
    op_name = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}
    n = f.n_instructions()
    # Pass 1: SSA nodes. node = (op, args, payload); work[i] = node id now in slot i.
    nodes: List[Tuple[str, Tuple[int, ...], Any]] = []
    work: Dict[int, int] = {}
    outputs: Dict[int, int] = {}
    for k in range(n):
        op = op_name.get(f.instruction_id(k), f"operation #{f.instruction_id(k)}")
        ins, outs = f.instruction_input(k), f.instruction_output(k)
        if op == "OP_INPUT":
            i, nz = ins
            row = f.sparsity_in(i).row()[nz]
            nodes.append(("name", (), names[i][row]))
            work[outs[0]] = len(nodes) - 1
        elif op == "OP_CONST":
            nodes.append(("const", (), float(f.instruction_constant(k))))
            work[outs[0]] = len(nodes) - 1
        elif op == "OP_OUTPUT":
            _, nz = outs
            outputs[f.sparsity_out(0).row()[nz]] = work[ins[0]]
        elif op == "OP_ASSIGN":
            work[outs[0]] = work[ins[0]]
        elif op in _UNARY or op in _BINARY:
            args = tuple(work[i] for i in ins)
            nodes.append((op, args, None))
            work[outs[0]] = len(nodes) - 1
        else:
            raise AmpcError(
                f"from_casadi: {f.name()} uses {op} (instruction {k}), which the problem "
                "file's expressions cannot state (they have + - * / ^, sin cos tan asin acos "
                "atan atan2 exp log sqrt sinh cosh tanh abs min max)"
            )
    # Pass 2: uses; an operation used more than once (or by two outputs) is a definition.
    uses = [0] * len(nodes)
    for op, args, _ in nodes:
        for a in args:
            uses[a] += 1
    for node in outputs.values():
        uses[node] += 1
    text: List[Optional[str]] = [None] * len(nodes)
    atomic: List[bool] = [True] * len(nodes)
    defs: List[str] = []
    counter = 0
    for i, (op, args, payload) in enumerate(nodes):
        if op == "name":
            text[i] = payload
            continue
        if op == "const":
            text[i] = _number(payload, f"{f.name()}, a constant")
            continue
        # A function's arguments need no parentheses; an operator's operands do unless atoms.
        call = op in _ATOMIC
        ops = [text[a] if call or atomic[a] else f"({text[a]})" for a in args]
        if op == "OP_CONSTPOW" and nodes[args[1]][0] == "const":
            ops[1] = _number(nodes[args[1]][2], "an exponent")
        e = (_UNARY.get(op) or _BINARY[op]).format(*ops)
        if uses[i] > 1:
            counter += 1
            name = f"{prefix}{counter}"
            while name in taken:
                counter += 1
                name = f"{prefix}{counter}"
            taken.add(name)
            defs.append(f"{name} = {e}")
            text[i], atomic[i] = name, True
        else:
            text[i], atomic[i] = e, op in _ATOMIC
    rhs = []
    for r in range(nx):
        node = outputs.get(r)
        rhs.append("0" if node is None else text[node])
    return defs, rhs
