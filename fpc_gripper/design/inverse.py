"""Inverse design: the finger that meets a gripper designer's targets (differential evolution)."""

import dataclasses
import math
import pathlib

import numpy as np
from scipy.optimize import brentq, differential_evolution, minimize

from fpc_gripper.model import batch
from fpc_gripper.model.discretisations.ccm_geometry import consistent_strain_map, from_scaled
from fpc_gripper.model.pipeline import finger_model
from fpc_gripper.model.validation import ENVELOPE
from .grid import base_design
from .parametric import model_settings

__all__ = ['Targets', 'DesignSearch', 'check_search', 'optimize', 'palm_radius',
           'peak_strain', 'write_outputs', 'PARAMETERS', 'default_bounds']

#: Parameters the search may vary: ActuatorDesign fields, and L, the free length (Lx - Lc,
#: moving Lx and Cx together so that the channel-free tip keeps its length).
PARAMETERS = ('prestrain', 'Cy', 'h3a', 'w1', 'L')
#: Pressures of the aperture curve between 0 and the budget (inclusive).
_CURVE_POINTS = 21
#: Objective of a design that is invalid or whose solves fail: far above any margin.
_INFEASIBLE = 1e3
#: Aperture margins are relative to max(|target|, this) [m].
_APERTURE_SCALE = 0.01
#: The paper's rigidity protocol [m].
_DELTA = 0.010


@dataclasses.dataclass(frozen=True)
class Targets:
    """
    What a gripper designer asks of a finger, SI units; None leaves a target out.

    Attributes
    ----------
    closed_aperture : float, optional
        Largest aperture at 0 kPa [m] (the gripper must close to it).
    open_aperture : float, optional
        Smallest aperture reached at or below `pressure_budget` [m].
    pressure_budget : float
        Largest gauge pressure the design may use [Pa].
    kx : float, optional
        Smallest K_x [N m^2] (eq. 22, delta x = 10 mm) with the gripper opened to
        `at_aperture` by pressure: at the least pressure whose aperture reaches it.
    tip_force : float, optional
        Smallest force [N] a fingertip presses at 0 kPa on an object of diameter
        `at_aperture` (the passive grasp of a normally closed gripper).
    at_aperture : float, optional
        Aperture of `kx` and `tip_force` [m].
    max_strain : float, optional
        Largest elastomer strain anywhere in the finger at 0 kPa to the budget
        (`peak_strain`, prestrain included) [-].

    Notes
    -----
    The aperture is the diameter of the circle through the fingertips, 2 (R + Z_tip)
    for identical fingers on a palm of radius R (`control.geometry`), negative once the
    tips cross the palm axis. ActuatorDesign's validity rules always apply.

    """

    closed_aperture: float = None
    open_aperture: float = None
    pressure_budget: float = 250e3
    kx: float = None
    tip_force: float = None
    at_aperture: float = None
    max_strain: float = None

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                    or not math.isfinite(value):
                raise ValueError(f'`{f.name}` must be a finite number, got {value!r}')
            object.__setattr__(self, f.name, float(value))
        if not self.pressure_budget > 0.0:
            raise ValueError(f'`pressure_budget` must be > 0 [Pa], got {self.pressure_budget}')
        # An aperture <= 0 would need the fingertips to cross the palm axis.
        for name in ('closed_aperture', 'open_aperture', 'at_aperture'):
            value = getattr(self, name)
            if value is not None and value <= 0.0:
                raise ValueError(f'`{name}` must be > 0 [m] (the diameter of the circle '
                                 f'through the fingertips), got {value}')
        for name in ('kx', 'tip_force', 'max_strain'):
            value = getattr(self, name)
            if value is not None and value <= 0.0:
                raise ValueError(f'`{name}` must be > 0, got {value}')
        if (self.kx is not None or self.tip_force is not None) and self.at_aperture is None:
            raise ValueError('`kx` and `tip_force` need `at_aperture` [m]')
        if not self.names():
            raise ValueError('give at least one target (closed_aperture, open_aperture, kx, '
                             'tip_force or max_strain)')

    def names(self):
        """Return the targets that are set, in a fixed order."""
        return [n for n in ('closed_aperture', 'open_aperture', 'kx', 'tip_force', 'max_strain')
                if getattr(self, n) is not None]


def default_bounds(base, parameters):
    """
    Search intervals of the parameters around a base design (SI).

    prestrain 0.15-0.40 (the default model's measured envelope); Cy from the narrowest
    channel the base ribs fit (2 (3t/2 + w1), unless w1 is searched too) to 0.98 Ly; h3a
    inside the fluidic layer (-0.9 h3b to 0.95 h2); w1 from a quarter to 1.25 times the
    base's; L from 0.6 to 1.3 times the base's free length.
    """
    out = {}
    for name in parameters:
        if name == 'prestrain':
            out[name] = (0.15, 0.40)
        elif name == 'Cy':
            low = 2.0 * (1.5 * base.t + (0.25 * base.w1 if 'w1' in parameters else base.w1))
            out[name] = (low if base.ribs else 0.3 * base.Ly, 0.98 * base.Ly)
        elif name == 'h3a':
            out[name] = (-0.9 * base.h3b, 0.95 * base.h2)
        elif name == 'w1':
            out[name] = (0.25 * base.w1, 1.25 * base.w1)
        elif name == 'L':
            out[name] = (0.6 * base.free_length, 1.3 * base.free_length)
    return out


def peak_strain(result, design):
    """
    Largest elastomer strain of an equilibrium, prestrain included [-].

    A fibre at height z has the axial strain e = eps - z k (docs/physics.md 11.2; the
    CCM's eps = b1 + (3 b3 + 2 d^2) x^2 and k = 2 d at x = 0 and L_i), and the
    prestretched EMC's material strain is eps0 + e. Strain is linear in z, so the
    extremes are at the layer faces: the PEMC's (-H/2, -h3) with the prestrain, and the
    fluidic layer's and regular EMC's (-h3, h1). The constraining layer is not an
    elastomer and is left out.

    Parameters
    ----------
    result : Result
        A finger's solve.
    design : ActuatorDesign

    Returns
    -------
    float

    """
    strains = result.strains
    if strains is not None:
        eps, kappa = strains[:, 0], strains[:, 1]
    else:
        q = result.state
        lengths = np.diff(result.segment_edges)
        if result.rung != 'ccm':
            q = consistent_strain_map(q)[0]
        c = from_scaled(q, lengths)
        x2 = np.stack([np.zeros(len(c)), lengths ** 2], axis=1)
        eps = (c[:, :1] + (3.0 * c[:, 1:2] + 2.0 * c[:, 3:4] ** 2) * x2).ravel()
        kappa = np.repeat(2.0 * c[:, 3], 2)
    pemc = [design.prestrain + eps - z * kappa for z in (-design.H / 2, -design.h3)]
    other = [eps - z * kappa for z in (-design.h3, design.h1)]
    return float(np.max(np.abs(np.concatenate(pemc + other))))


class DesignSearch:
    """
    The objective of the inverse design: the targets' margins of candidate designs.

    Parameters
    ----------
    targets : Targets
    parameters : sequence of str
        From `PARAMETERS`.
    base : ActuatorDesign
    palm_radius : float
        [m].
    settings : ModelSettings

    """

    def __init__(self, targets, parameters, base, palm_radius, settings):
        self.targets = targets
        self.parameters = tuple(parameters)
        self.base = base
        self.palm_radius = float(palm_radius)
        self.settings = settings
        self.pressures = np.linspace(0.0, targets.pressure_budget, _CURVE_POINTS)
        self.history = []

    def design(self, x):
        """Return the ActuatorDesign of parameter vector x, or (None, why) if invalid."""
        fields = dict(zip(self.parameters, (float(v) for v in x)))
        if 'L' in fields:
            free = fields.pop('L')
            lx = self.base.Lc + free
            fields.update(Lx=lx, Cx=lx - (self.base.Lx - self.base.Cx))
        try:
            return self.base.replace(**fields), ''
        except (ValueError, TypeError) as error:
            return None, str(error)

    def aperture(self, z_tip):
        """Aperture 2 (R + Z_tip) [m] of identical fingers, for tip Z [m]."""
        return 2.0 * (self.palm_radius + np.asarray(z_tip, dtype=float))

    def evaluate(self, xs):
        """
        Metrics of candidates xs (S, n): a list of dicts (None for invalid or failed ones).

        Each dict holds the aperture curve over `pressures`, the closed and open
        apertures, K_x at 0 kPa and whatever the targets need (K_x or tip force at the
        aperture, peak strain), and the margins.
        """
        xs = np.atleast_2d(xs)
        designs = [self.design(x)[0] for x in xs]
        valid = [k for k, d in enumerate(designs) if d is not None]
        out = [None] * len(xs)
        if not valid:
            return out
        chosen = [designs[k] for k in valid]
        grid = batch.solve_grid(chosen, self.pressures, settings=self.settings)
        kx0 = batch.rigidity_grid(chosen, [0.0], 'x', _DELTA, self.settings)
        for j, k in enumerate(valid):
            if not grid.success[j, :, 0].all():
                continue
            metrics = self._metrics(designs[k], grid, j, float(kx0.value[j, 0]))
            if metrics is not None:
                out[k] = metrics
        for x, metrics in zip(xs, out):
            self.history.append((np.array(x, dtype=float), metrics))
        return out

    def _metrics(self, design, grid, j, kx0):
        t = self.targets
        curve = self.aperture(grid.tip[j, :, 0, 1])
        m = {'apertures': curve, 'closed_aperture': float(curve[0]),
             'open_aperture': float(curve.max()), 'kx_closed': kx0}
        if t.max_strain is not None:
            m['max_strain'] = max(peak_strain(grid.result(j, p), design)
                                  for p in range(self.pressures.size))
        model = finger_model(design, self.settings)
        if t.kx is not None:
            try:
                m['kx'], m['kx_pressure'] = self._kx_at(model, curve, t.at_aperture)
            except ValueError:
                # A solve failed inside the bracket: no trustworthy K_x, an infeasible design.
                return None
        if t.tip_force is not None:
            gap = (t.at_aperture / 2.0 - self.palm_radius) - grid.tip[j, 0, 0, 1]
            force = 0.0
            if gap > 0.0:
                k = model.rigidity(0.0, 'z', gap)
                if not k.success:
                    return None
                force = k.force
            m['tip_force'] = float(force)
        m['margins'] = self.margins(m)
        return m

    def _kx_at(self, model, curve, aperture):
        """K_x [N m^2] at the least pressure [Pa] whose aperture reaches `aperture`."""
        reached = np.flatnonzero(curve >= aperture)
        if not reached.size:
            return 0.0, math.nan
        i = int(reached[0])
        pressure = 0.0
        if i > 0:
            def gap(p):
                result = model.solve(p)
                if not result.success:
                    raise ValueError(f'solve failed at {p} Pa: {result.message}')
                return float(self.aperture(result.tip[1])) - aperture
            pressure = brentq(gap, self.pressures[i - 1], self.pressures[i], xtol=1.0,
                              rtol=1e-10)
        k = model.rigidity(pressure, 'x', _DELTA)
        return (float(k.value) if k.success else 0.0), float(pressure)

    def margins(self, m):
        """Margin of every target, > 0 where met, in SI: (value, required, margin, scale)."""
        t = self.targets
        out = {}
        for name in t.names():
            required = getattr(t, name)
            value = m[name]
            margin = required - value if name in ('closed_aperture', 'max_strain') \
                else value - required
            scale = max(abs(required), _APERTURE_SCALE) if 'aperture' in name \
                else abs(required)
            out[name] = (value, required, margin, scale)
        return out

    def objective(self, xs):
        """Minus the smallest relative margin of each candidate, xs (n,) or (n, S)."""
        xs = np.asarray(xs, dtype=float)
        single = xs.ndim == 1
        metrics = self.evaluate(xs[None, :] if single else xs.T)
        values = np.array([_INFEASIBLE if m is None else
                           -min(mg / sc for _, _, mg, sc in m['margins'].values())
                           for m in metrics])
        return float(values[0]) if single else values


@dataclasses.dataclass
class InverseDesign:
    """
    Outcome of `optimize`, OptimizeResult-like.

    Attributes
    ----------
    design : ActuatorDesign or None
        The best design found.
    x : dict
        Its parameters.
    success : bool
        Every target met.
    status : str
        'met' or 'unreachable'.
    message : str
    margins : pandas.DataFrame
        One row per target: value, required, margin (SI, > 0 where met), relative
        margin, met, and best_alone (the best margin any evaluated design reached on
        that target alone).
    pareto : pandas.DataFrame
        Non-dominated (stroke, pressure budget, K_x at 0 kPa) of every evaluated design.
    history : pandas.DataFrame
        Every evaluated candidate with its worst relative margin.
    nfev : int
    metrics : dict
        The best design's metrics.
    palm_radius : float
        [m].

    """

    design: object
    x: dict
    success: bool
    status: str
    message: str
    margins: object
    pareto: object
    history: object
    nfev: int
    metrics: dict
    palm_radius: float

    def report(self):
        """Return the margins as text, with the verdict."""
        lines = [f'{self.status.upper()}: {self.message}',
                 '  ' + ', '.join(f'{k} = {v:.6g}' for k, v in self.x.items())]
        for row in self.margins.itertuples(index=False):
            lines.append(f'  {row.target:16s} value {row.value:11.5g}  required '
                         f'{row.required:11.5g}  margin {row.margin:+11.4g} '
                         f'({row.relative_margin:+.1%})  {"met" if row.met else "NOT MET"}'
                         f'  best alone {row.best_alone:+.4g}')
        return '\n'.join(lines)


def palm_radius(gripper=None):
    """Return the palm radius of a gripper config (default gripper_paper.yaml) [m]."""
    from fpc_gripper.io.config import load_gripper_config
    return load_gripper_config(gripper).palm_radius


def check_search(targets, parameters, design, bounds=None):
    """
    Check a search's inputs before any solve; return (parameters, base design, box).

    Raises
    ------
    TypeError, ValueError
        Naming the argument: unknown or repeated parameters, bounds of unsearched
        parameters or not finite with low < high, a pressure budget beyond the model's
        envelope (`validation.ENVELOPE`, a multiple of the design's max_pressure).

    """
    if not isinstance(targets, Targets):
        raise TypeError(f'`targets` must be a Targets, got {type(targets).__name__}')
    parameters = tuple(parameters)
    unknown = [p for p in parameters if p not in PARAMETERS]
    if unknown or not parameters or len(set(parameters)) != len(parameters):
        raise ValueError(f'`parameters` must be distinct names from {PARAMETERS}, '
                         f'got {parameters}')
    base = base_design(design)
    top = ENVELOPE.pressure_factor * base.max_pressure
    if targets.pressure_budget > top:
        raise ValueError(f'`pressure_budget` must be <= {top:.6g} [Pa], '
                         f'{ENVELOPE.pressure_factor:g} x max_pressure of the design (the '
                         f'envelope of the model), got {targets.pressure_budget:.6g}')
    limits = default_bounds(base, parameters)
    for name, interval in dict(bounds or {}).items():
        if name not in parameters:
            raise ValueError(f'`bounds` names {name!r}, which is not searched {parameters}')
        low, high = (float(v) for v in interval)
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f'`bounds[{name!r}]` must be finite with low < high, '
                             f'got {interval!r}')
        limits[name] = (low, high)
    return parameters, base, limits


def optimize(targets, parameters=('prestrain', 'Cy', 'h3a'), design=None, bounds=None,
             gripper=None, model='default', seed=0, maxiter=30, popsize=10, polish=True,
             progress=None):
    """
    Search the design that meets the targets best: differential evolution, then Powell.

    The objective is the smallest of the targets' relative margins (positive where met),
    maximised: a design that meets every target has it >= 0, and where none does the
    result is the design whose worst shortfall is least, reported as unreachable with
    that margin. Candidates of a generation are solved together on the batched engine
    (`batch.solve_grid` over the aperture curve, `batch.rigidity_grid` for K_x at 0 kPa),
    every finger built by the pipeline. Invalid designs (ActuatorDesign's rules) and
    failed solves are infeasible. Same inputs and seed, same result.

    Parameters
    ----------
    targets : Targets
    parameters : sequence of str
        Searched, from `PARAMETERS`.
    design : ActuatorDesign or path, optional
        Base design (the other fields); default the paper's finger.
    bounds : mapping of str to (float, float), optional
        Overrides of `default_bounds`.
    gripper : path, optional
        Gripper config whose palm radius sets the aperture (default gripper_paper.yaml).
    model : {'default', 'paper'} or ModelSettings
    seed : int
    maxiter, popsize : int
        Differential evolution's generations and population per parameter.
    polish : bool
        Finish with bounded Powell from the best candidate.
    progress : bool, optional
        Progress bar per generation.

    Returns
    -------
    InverseDesign

    """
    import pandas as pd
    from .runner import _bar
    parameters, base, limits = check_search(targets, parameters, design, bounds)
    search = DesignSearch(targets, parameters, base, palm_radius(gripper),
                          model_settings(model))
    box = [limits[p] for p in parameters]
    with _bar(int(maxiter), progress, 'generation') as bar:
        found = differential_evolution(search.objective, box, maxiter=int(maxiter),
                                       popsize=int(popsize), rng=int(seed), polish=False,
                                       vectorized=True, updating='deferred', tol=0.0,
                                       init='sobol', callback=lambda *a, **k: bar.update(1))
    best_x, best_f = found.x, found.fun
    if polish and best_f < _INFEASIBLE:
        local = minimize(search.objective, best_x, method='Powell', bounds=box,
                         options={'maxfev': 60 * len(parameters), 'xtol': 1e-4,
                                  'ftol': 1e-6})
        if local.fun < best_f:
            best_x, best_f = local.x, local.fun
    best, why = search.design(best_x)
    metrics = search.evaluate(best_x)[0] if best is not None else None
    x = dict(zip(parameters, (float(v) for v in best_x)))
    history = _history(search, parameters)
    if metrics is None:
        margins = pd.DataFrame(columns=['target', 'value', 'required', 'margin',
                                        'relative_margin', 'met', 'best_alone'])
        return InverseDesign(best, x, False, 'unreachable',
                             f'no valid design with converged solves found ({why})',
                             margins, _pareto(search, parameters), history, len(history),
                             {}, search.palm_radius)
    margins = _margins(search, metrics)
    met = bool(margins['met'].all())
    worst = margins.loc[margins['relative_margin'].idxmin()]
    message = ('every target met; smallest relative margin '
               f'{worst.relative_margin:+.2%} ({worst.target})' if met else
               f'{", ".join(margins.loc[~margins["met"], "target"])} not reached; best '
               f'worst margin found {worst.relative_margin:+.2%} ({worst.target}: '
               f'{worst.value:.4g} against {worst.required:.4g})')
    return InverseDesign(best, x, met, 'met' if met else 'unreachable', message, margins,
                         _pareto(search, parameters), history, len(history), metrics,
                         search.palm_radius)


def _margins(search, metrics):
    import pandas as pd
    rows = []
    for name, (value, required, margin, scale) in metrics['margins'].items():
        alone = max((m['margins'][name][2] for _, m in search.history if m is not None),
                    default=margin)
        rows.append({'target': name, 'value': value, 'required': required, 'margin': margin,
                     'relative_margin': margin / scale, 'met': margin >= 0.0,
                     'best_alone': max(alone, margin)})
    return pd.DataFrame(rows)


def _history(search, parameters):
    import pandas as pd
    rows = []
    for x, m in search.history:
        row = dict(zip(parameters, x))
        row['feasible'] = m is not None
        row['worst_relative_margin'] = (min(mg / sc for _, _, mg, sc in m['margins'].values())
                                        if m is not None else math.nan)
        rows.append(row)
    return pd.DataFrame(rows)


def _pareto(search, parameters):
    """Non-dominated (max stroke, min pressure budget, max K_x at 0 kPa) points."""
    import pandas as pd
    rows, seen = [], set()
    for x, m in search.history:
        key = tuple(np.round(x, 12))
        if m is None or key in seen:
            continue
        seen.add(key)
        curve = m['apertures']
        for j in range(1, search.pressures.size):
            row = dict(zip(parameters, x))
            row.update(pressure_budget_pa=search.pressures[j],
                       stroke_m=float(curve[:j + 1].max() - curve[0]),
                       kx_closed_nm2=m['kx_closed'], closed_aperture_m=m['closed_aperture'],
                       open_aperture_m=float(curve[:j + 1].max()))
            rows.append(row)
    frame = pd.DataFrame(rows)
    if frame.empty:
        return frame
    keep = np.zeros(len(frame), dtype=bool)
    stroke = frame['stroke_m'].to_numpy()
    budget = frame['pressure_budget_pa'].to_numpy()
    kx = frame['kx_closed_nm2'].to_numpy()
    for level in np.unique(budget):
        here = np.flatnonzero(budget == level)
        rivals = np.flatnonzero(budget <= level)
        for i in here:
            better = (stroke[rivals] >= stroke[i]) & (kx[rivals] >= kx[i])
            strictly = (stroke[rivals] > stroke[i]) | (kx[rivals] > kx[i]) | \
                (budget[rivals] < level)
            keep[i] = not np.any(better & strictly)
    return frame[keep].sort_values(['pressure_budget_pa', 'stroke_m']).reset_index(drop=True)


def write_outputs(result, out_dir):
    """
    Write an optimisation's files: the actuator and gripper YAMLs, margins, Pareto CSV/PNG.

    ``actuator.yaml`` is the best design (`ActuatorDesign.to_yaml`); ``gripper.yaml`` the
    three-finger gripper of gripper_paper.yaml with that actuator and the same palm, so
    ``model_node --ros-args -p gripper_config:=DIR/gripper.yaml`` runs it. When a target
    is not met the closest design is ``closest_actuator.yaml`` instead, and there is no
    gripper.yaml: nothing of an unmet search looks deployable.

    Returns
    -------
    list of pathlib.Path

    """
    import yaml
    from fpc_gripper.io.config import default_gripper_config_path
    from .charts import pyplot, save_figure, write_table
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    if result.design is not None and not result.success:
        result.design.to_yaml(out_dir / 'closest_actuator.yaml')
        files.append(out_dir / 'closest_actuator.yaml')
    elif result.design is not None:
        result.design.to_yaml(out_dir / 'actuator.yaml')
        gripper = yaml.safe_load(default_gripper_config_path().read_text())
        gripper['actuator'] = 'actuator.yaml'
        gripper['palm_radius'] = result.palm_radius
        for finger in gripper['fingers']:
            finger.pop('design', None)
        (out_dir / 'gripper.yaml').write_text(
            '# Gripper of fpc-design optimize: its actuator.yaml on every finger.\n'
            + yaml.safe_dump(gripper, sort_keys=False))
        files += [out_dir / 'actuator.yaml', out_dir / 'gripper.yaml']
    files.append(write_table(result.margins, out_dir / 'margins.csv'))
    files.append(write_table(result.pareto, out_dir / 'pareto.csv'))
    files.append(write_table(result.history, out_dir / 'history.csv'))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.8))
    if not result.pareto.empty:
        points = ax.scatter(result.pareto['pressure_budget_pa'] / 1e3,
                            result.pareto['stroke_m'] * 1e3,
                            c=result.pareto['kx_closed_nm2'] * 1e3, cmap='viridis', s=18)
        fig.colorbar(points, ax=ax, label='$K_x$ at 0 kPa [10⁻³ N·m²]')
    ax.set_xlabel('pressure budget [kPa]')
    ax.set_ylabel('stroke (open - closed aperture) [mm]')
    ax.set_title(f'Pareto front of {len(result.history)} evaluated designs; '
                 f'{result.status}', fontsize=9)
    ax.grid(alpha=0.3)
    files.append(save_figure(fig, out_dir / 'pareto.png'))
    return files
