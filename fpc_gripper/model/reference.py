"""Which accuracy reference a tolerance speaks of: the rod, or the continuum rung's floor."""

__all__ = ['REFERENCES', 'CONTINUUM_FLOOR', 'CORRECTED_FLOOR', 'rod_tolerance']

#: The references a tip tolerance can be measured against: 'rod' (the ladder's error model,
#: bench/bench_ladder.py) or 'continuum' (the 2-D FE, bench/bench_continuum.py).
REFERENCES = ('rod', 'continuum')
#: The beam floor against the continuum [m]: the largest tip distance between the rod
#: (ribs exact) and the continuum FE (h = 1 mm, ribs exact) over the reference table's
#: unpressurised scenes (prestrain 0.15-0.40, unloaded and +-0.5 N along X and Z), from
#: bench/results/continuum.json. Written here as a number (it is a measurement, not
#: recomputed at import); tests/model/test_reference_floor.py checks it against the file.
CONTINUUM_FLOOR = 2.596e-3
#: The continuum-corrected rung's floor against the continuum [m]: the largest tip distance
#: between `corrected.CorrectedSolver` with `CONTINUUM_FIT` (ModelSettings(physics=
#: 'continuum')) and the same FE scenes, from bench/results/continuum_fit.json ('stored',
#: 'max_error_mm'). A number, checked against the file by tests/model/test_reference_floor.py.
CORRECTED_FLOOR = 0.1911e-3
#: Largest gauge pressure the continuum reference covers [Pa]: under pressure the FE's
#: homogenised channel is indicative only (docs/physics.md, section 18).
CONTINUUM_MAX_PRESSURE = 0.0


def rod_tolerance(tolerance, reference, pressure):
    """
    Return the tolerance against the rod that meets `tolerance` against `reference`.

    Against the continuum a rung's tip error is at most its error against the rod plus
    the rod's against the continuum, so the rod-referenced tolerance is the given one
    minus `CONTINUUM_FLOOR`; a tolerance at or below the floor cannot be met by any rung of
    the paper's physics and is refused, naming ``ModelSettings(physics='continuum')`` when
    it is above that rung's `CORRECTED_FLOOR`.

    Parameters
    ----------
    tolerance : float
        Tip-position tolerance [m], > 0.
    reference : {'rod', 'continuum'}
    pressure : float
        The scene's gauge pressure [Pa].

    Raises
    ------
    ValueError
        Naming `reference` if unknown, `pressure` if the continuum reference does not
        cover it, and `tolerance` if it is below the beam floor.

    """
    if reference not in REFERENCES:
        raise ValueError(f'`reference` must be one of {list(REFERENCES)}, got {reference!r}')
    if reference == 'rod':
        return tolerance
    if pressure > CONTINUUM_MAX_PRESSURE:
        raise ValueError(f"`pressure` {pressure:g} [Pa]: reference='continuum' covers "
                         'unpressurised scenes only (the FE channel under pressure is '
                         'indicative, docs/physics.md section 18)')
    if tolerance <= CONTINUUM_FLOOR:
        way = (f"; the continuum-corrected rung, ModelSettings(physics='continuum'), is "
               f'within {CORRECTED_FLOOR:g} m of the FE there and meets it'
               if tolerance > CORRECTED_FLOOR else
               f"; even the continuum-corrected rung (physics='continuum') is "
               f'{CORRECTED_FLOOR:g} m off')
        raise ValueError(f'`tolerance` {tolerance:g} [m] is below the beam floor against the '
                         f'continuum, {CONTINUUM_FLOOR:g} m (rod against the 2-D FE, '
                         'bench/results/continuum.json): no rung of the paper physics meets '
                         f'it{way}')
    return tolerance - CONTINUUM_FLOOR
