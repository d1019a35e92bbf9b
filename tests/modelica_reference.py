"""Reference simulation of the bundled plants' Modelica models (.mo) with pymoca + CasADi.

Used by the tests to check that each plant's FMU (built from C) implements the same equations as its
Modelica model. Not a test module itself.

    simulate_modelica(mo_path, parameters, input_sequence, sample_time_s, n_steps)
        -> {output name: ndarray of shape (n_steps + 1,)}

How a model is turned into an ODE:

* `pymoca.parser.parse` + `pymoca.backends.casadi.generator.generate` give the flattened model as
  implicit residual equations F(der(x), x, z, u, p, t) = 0 (z: algebraic variables, which include
  the outputs that are not states).
* The equations are causalised: the structural Jacobian dF/d[der(x); z] is put in block triangular
  form (CasADi `Sparsity.btf`) and the blocks are solved one after the other, symbolically. Each
  block must be affine in its own unknowns once the earlier blocks are substituted (true for explicit
  models written as `v = expression`, including if-expressions whose conditions use earlier
  variables); anything else (a genuine algebraic loop) raises NotImplementedError.
* Initial states are the `start` values of the states (expressions of the parameters, e.g.
  `Real x(start = x0, fixed = true)`); states that are not `fixed` are solved from the initial
  equations, if any.
* The explicit ODE der(x) = f(t, x, u, p) is integrated with CVODES (Adams, functional iteration,
  abstol = reltol = 1e-12) one sample interval [t_k, t_k + Ts] at a time, the solver restarted at each
  t_k, with the inputs held constant over the interval (zero-order hold, like one co-simulation doStep
  per sample). (CasADi's own piecewise-constant `u` on an output grid is not used: CVODES steps over the
  grid points and interpolates, smearing the input jumps, which costs ~1e-6 accuracy.) Outputs at t_k are evaluated from x(t_k) with the inputs of the
  interval that ended at t_k (like reading outputs after doStep); at t = 0 with the inputs' start
  values (like reading outputs after initialisation).

pymoca 0.12 maps the Modelica operator `/` to `MX.__div__`, which CasADi >= 3.6 no longer has (Python 3
uses `__truediv__`); importing this module repairs that entry of pymoca's operator table.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pymoca.backends.casadi.generator as _generator
import pymoca.parser

if not hasattr(ca.MX, "__div__"):
    _generator.OP_MAP["/"] = "__truediv__"

INTEGRATOR_TOL = 1e-12


@dataclass
class ModelicaModel:
    """A Modelica model reduced to an explicit ODE with outputs, as CasADi functions."""
    name: str
    state_names: list[str]
    input_names: list[str]
    input_starts: np.ndarray
    parameter_names: list[str]
    parameter_defaults: dict[str, float]
    output_names: list[str]
    rhs: ca.Function          # (t, x, u, p) -> der(x)
    outputs: ca.Function      # (t, x, u, p) -> outputs
    initial_state: ca.Function  # (p) -> x(0)


def _scalar_symbols(variables, what):
    syms = []
    for v in variables:
        s = v.symbol
        if s.numel() != 1:
            raise NotImplementedError(f"{what} {s.name()} is not a scalar (arrays are not supported here)")
        syms.append(s)
    return syms


def _constant_value(expr, what) -> float:
    """A float from a number or a symbol-free CasADi expression."""
    if isinstance(expr, (int, float, np.floating, np.integer)):
        return float(expr)
    expr = ca.MX(expr)
    if not expr.is_constant() and ca.symvar(expr):
        raise NotImplementedError(f"{what} is not a numeric literal: {expr}")
    return float(ca.evalf(expr))


def _causalise(residuals: ca.MX, unknowns: list[ca.MX]) -> list[ca.MX]:
    """Solve residuals(unknowns, ...) = 0 for the unknowns, block by block, symbolically.

    Returns one expression per unknown in terms of the other symbols only.
    """
    n = len(unknowns)
    if residuals.numel() != n:
        raise ValueError(f"{residuals.numel()} equations for {n} unknowns: the model is not balanced")
    if n == 0:
        return []
    w = ca.vertcat(*unknowns)
    sp = ca.jacobian(residuals, w).sparsity()
    nb, rowperm, colperm, rowblock, colblock, _, _ = sp.btf()
    if nb == 0 or rowblock[-1] != n or colblock[-1] != n:
        raise ValueError("the equations are structurally singular in the derivatives and algebraic variables")
    blocks = []
    for b in range(nb):
        rows = [rowperm[i] for i in range(rowblock[b], rowblock[b + 1])]
        cols = [colperm[i] for i in range(colblock[b], colblock[b + 1])]
        if len(rows) != len(cols):
            raise ValueError("the equations are structurally singular in the derivatives and algebraic variables")
        blocks.append((rows, cols))
    # Which unknowns each equation mentions (structurally).
    col_of_row = [set() for _ in range(n)]
    colind, row = sp.colind(), sp.row()
    for c in range(n):
        for k in range(colind[c], colind[c + 1]):
            col_of_row[row[k]].add(c)

    solution: dict[int, ca.MX] = {}
    pending = list(blocks)
    while pending:
        for idx, (rows, cols) in enumerate(pending):
            needed = set().union(*(col_of_row[r] for r in rows)) - set(cols)
            if needed <= solution.keys():
                break
        else:  # pragma: no cover - btf always yields a solvable order
            raise ValueError("could not order the equations")
        rows, cols = pending.pop(idx)
        known = sorted(solution)
        fb = ca.vertcat(*[residuals[r] for r in rows])
        if known:
            fb = ca.substitute([fb], [unknowns[c] for c in known], [solution[c] for c in known])[0]
        wb = ca.vertcat(*[unknowns[c] for c in cols])
        a = ca.jacobian(fb, wb)
        if ca.depends_on(a, wb):
            names = ", ".join(unknowns[c].name() for c in cols)
            raise NotImplementedError(f"equations for {names} are not affine in them (nonlinear algebraic loop)")
        b = ca.substitute(fb, wb, ca.MX.zeros(wb.shape))
        x = -b / a if len(cols) == 1 else -ca.solve(a, b)
        for i, c in enumerate(cols):
            solution[c] = x[i]
    return [solution[c] for c in range(n)]


def load_modelica(mo_path: str | os.PathLike, model_name: str | None = None) -> ModelicaModel:
    """Parse a .mo file with pymoca and reduce the model to explicit CasADi functions (cached)."""
    path = Path(mo_path).resolve()
    key = (str(path), path.stat().st_mtime_ns, model_name)
    if key not in _CACHE:
        _CACHE[key] = _load(path, model_name or path.stem)
    return _CACHE[key]


_CACHE: dict[tuple, ModelicaModel] = {}


def _load(path: Path, model_name: str) -> ModelicaModel:
    ast = pymoca.parser.parse(path.read_text())
    if ast is None:
        raise ValueError(f"{path}: pymoca could not parse the file")
    m = _generator.generate(ast, model_name)
    if m.delay_states:
        raise NotImplementedError("delay() is not supported")

    t = m.time
    x = _scalar_symbols(m.states, "state")
    dx = _scalar_symbols(m.der_states, "state derivative")
    z = _scalar_symbols(m.alg_states, "variable")
    u = _scalar_symbols(m.inputs, "input")
    p = _scalar_symbols(m.parameters, "parameter")
    c = _scalar_symbols(m.constants, "constant")

    # Constants by value. Parameter bindings must be numbers (no bindings to other parameters).
    const_vals = [ca.MX(_constant_value(v.value, f"constant {v.symbol.name()}")) for v in m.constants]

    def fix_constants(expr):
        expr = ca.MX(expr)
        return ca.substitute([expr], c, const_vals)[0] if c else expr

    param_defaults = {}
    for v in m.parameters:
        param_defaults[v.symbol.name()] = _constant_value(fix_constants(v.value), f"default of parameter {v.symbol.name()}")

    residuals = fix_constants(ca.vertcat(*m.equations)) if m.equations else ca.MX(0, 1)
    sol = _causalise(residuals, dx + z)
    dx_sol, z_sol = sol[:len(dx)], sol[len(dx):]

    all_vars = {s.name(): s for s in x + z}
    z_by_name = {s.name(): e for s, e in zip(z, z_sol)}
    out_exprs = []
    for name in m.outputs:
        out_exprs.append(z_by_name[name] if name in z_by_name else all_vars[name])

    T, X, U, P = t, ca.vertcat(*x), ca.vertcat(*u), ca.vertcat(*p)
    rhs = ca.Function("rhs", [T, X, U, P], [ca.vertcat(*dx_sol)], ["t", "x", "u", "p"], ["dx"])
    outputs = ca.Function("outputs", [T, X, U, P], [ca.vertcat(*out_exprs)], ["t", "x", "u", "p"], ["y"])

    # Initial states: start values of the fixed states; the others from the initial equations.
    starts = [fix_constants(v.start) for v in m.states]
    fixed = [bool(_constant_value(fix_constants(v.fixed), "fixed")) for v in m.states]
    x0 = list(starts)
    init_eqs = [fix_constants(e) for e in m.initial_equations]
    if init_eqs:
        free = [i for i, f in enumerate(fixed) if not f]
        g = ca.vertcat(*init_eqs)
        # Initial equations may mention derivatives and algebraic variables: use their solutions.
        g = ca.substitute([g], dx + z, dx_sol + z_sol)[0]
        g = ca.substitute([g], [x[i] for i in range(len(x)) if fixed[i]], [starts[i] for i in range(len(x)) if fixed[i]])[0]
        g = ca.substitute([g], [t], [ca.MX(0.0)])[0]
        free_sol = _causalise(g, [x[i] for i in free])
        for i, e in zip(free, free_sol):
            x0[i] = e
    x0_expr = ca.vertcat(*x0) if x0 else ca.MX(0, 1)
    # Start values and initial equations may use parameters (and constants) only.
    initial_state = ca.Function("x0", [P], [x0_expr], ["p"], ["x0"])

    # SX versions evaluate much faster inside the integrator.
    try:
        rhs, outputs, initial_state = rhs.expand(), outputs.expand(), initial_state.expand()
    except Exception:  # pragma: no cover - keep MX if an operation cannot be expanded
        pass

    input_starts = np.array([_constant_value(fix_constants(v.start), f"start of input {v.symbol.name()}")
                             for v in m.inputs], dtype=float)
    return ModelicaModel(
        name=model_name,
        state_names=[s.name() for s in x],
        input_names=[s.name() for s in u],
        input_starts=input_starts,
        parameter_names=[s.name() for s in p],
        parameter_defaults=param_defaults,
        output_names=list(m.outputs),
        rhs=rhs,
        outputs=outputs,
        initial_state=initial_state,
    )


def simulate_modelica(mo_path, parameters: dict | None, input_sequence: dict, sample_time_s: float,
                      n_steps: int, model_name: str | None = None) -> dict[str, np.ndarray]:
    """Simulate a Modelica model over n_steps samples of sample_time_s with zero-order-hold inputs.

    Args:
        mo_path: the .mo file; the model is the class named like the file (or `model_name`).
        parameters: {parameter name: value} overriding the model's defaults (None: all defaults).
        input_sequence: {input name: array of shape (n_steps,)}; entry k is held over
            [k Ts, (k+1) Ts). Inputs left out stay at their start value.
        sample_time_s: Ts, s.
        n_steps: number of samples.

    Returns:
        {output name: array of shape (n_steps + 1,)}: the outputs at t = 0, Ts, ..., n_steps Ts.
    """
    model = load_modelica(mo_path, model_name)
    parameters = dict(parameters or {})
    unknown = set(parameters) - set(model.parameter_names)
    if unknown:
        raise KeyError(f"{model.name} has no parameter(s) {sorted(unknown)}; it has {model.parameter_names}")
    unknown = set(input_sequence) - set(model.input_names)
    if unknown:
        raise KeyError(f"{model.name} has no input(s) {sorted(unknown)}; it has {model.input_names}")
    if not (sample_time_s > 0 and np.isfinite(sample_time_s)):
        raise ValueError(f"sample_time_s must be positive, got {sample_time_s!r}")
    n_steps = int(n_steps)
    if n_steps < 0:
        raise ValueError("n_steps must be >= 0")

    p = np.array([float(parameters.get(n, model.parameter_defaults[n])) for n in model.parameter_names])
    u = np.tile(model.input_starts[:, None], (1, n_steps))
    for i, name in enumerate(model.input_names):
        if name in input_sequence:
            seq = np.asarray(input_sequence[name], dtype=float)
            if seq.shape != (n_steps,):
                raise ValueError(f"input {name}: expected shape ({n_steps},), got {seq.shape}")
            u[i] = seq

    x0 = np.array(model.initial_state(p), dtype=float).reshape(-1)
    nx = x0.size
    times = sample_time_s * np.arange(n_steps + 1)
    if n_steps and nx:
        # One integration per sample interval (restarting the solver at each input change), chained
        # over the steps by mapaccum; the interval's inputs and start time are appended to p.
        steps = _stepper(model, sample_time_s, n_steps)
        extra = np.vstack([np.tile(p[:, None], (1, n_steps)), u, times[None, :-1]])
        xs = np.array(steps(x0, extra), dtype=float).reshape(nx, n_steps)
        xs = np.hstack([x0[:, None], xs])
    else:
        xs = np.tile(x0[:, None], (1, n_steps + 1))

    # Outputs: at t_0 with the input starts, at t_k (k >= 1) with the inputs held over the last interval.
    u_at = np.hstack([model.input_starts[:, None], u]) if model.input_names else np.zeros((0, n_steps + 1))
    y = np.array(model.outputs.map(n_steps + 1)(times[None, :], xs, u_at, np.tile(p[:, None], (1, n_steps + 1))),
                 dtype=float).reshape(len(model.output_names), n_steps + 1)
    return {name: y[i].copy() for i, name in enumerate(model.output_names)}


_STEPPERS: dict[tuple, ca.Function] = {}


def _stepper(model: ModelicaModel, ts: float, n_steps: int) -> ca.Function:
    """(x0, [p; u_k; t_k] for k < n_steps) -> x(t_1), ..., x(t_n): one solver run per interval."""
    key = (id(model), ts, n_steps)
    if key not in _STEPPERS:
        nx, nu, npar = len(model.state_names), len(model.input_names), len(model.parameter_names)
        tau = ca.SX.sym("tau")                  # time since the start of the interval
        x = ca.SX.sym("x", nx)
        pu = ca.SX.sym("pu", npar + nu + 1)     # parameters, held inputs, interval start time
        p, u, t0 = pu[:npar], pu[npar:npar + nu], pu[npar + nu]
        dae = {"t": tau, "x": x, "p": pu, "ode": model.rhs(t0 + tau, x, u, p)}
        # Adams with functional iteration: the plants are not stiff, and no Jacobian is needed (the
        # TwoTank's sqrt has an infinite slope at an empty tank, which breaks Newton iterations).
        opts = {"abstol": INTEGRATOR_TOL, "reltol": INTEGRATOR_TOL, "max_num_steps": 1_000_000,
                "linear_multistep_method": "adams", "nonlinear_solver_iteration": "functional"}
        integ = ca.integrator(f"{model.name}_interval", "cvodes", dae, 0.0, ts, opts)
        x_sym, pu_sym = ca.MX.sym("x", nx), ca.MX.sym("pu", npar + nu + 1)
        one = ca.Function("one_step", [x_sym, pu_sym], [integ(x0=x_sym, p=pu_sym)["xf"]])
        _STEPPERS[key] = one.mapaccum("steps", n_steps)
    return _STEPPERS[key]


def modelica_interface(mo_path: str | os.PathLike, model_name: str | None = None) -> dict:
    """The public interface of a model: {"description": str, "variables": {name: {...}}}.

    Each variable (public, non-constant components: inputs, outputs, parameters) has "causality"
    ("input", "output", "parameter" or "local"), "start" (a parameter's binding or an input's start
    attribute, when a number; else None), "unit" (None when absent) and "description".
    """
    import pymoca.ast
    import pymoca.tree

    path = Path(mo_path)
    name = model_name or path.stem
    ast = pymoca.parser.parse(path.read_text())
    cls = pymoca.tree.flatten(ast, pymoca.ast.ComponentRef.from_string(name)).classes[name]

    def value(node):
        v = getattr(node, "value", None)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    variables = {}
    for sym in sorted(cls.symbols.values(), key=lambda s: s.order):
        if getattr(sym.visibility, "name", sym.visibility) not in ("PUBLIC", "public") or "constant" in sym.prefixes:
            continue
        causality = next((c for c in ("input", "output", "parameter") if c in sym.prefixes), "local")
        start = value(sym.value) if causality == "parameter" else value(sym.start)
        variables[sym.name] = {
            "causality": causality,
            "start": start if isinstance(start, float) else None,
            "unit": value(sym.unit),
            "description": sym.comment,
        }
    return {"description": cls.comment, "variables": variables}
