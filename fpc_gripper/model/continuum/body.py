"""The finger's side view as cells of layers, channel band, ribs and solid tip, from a design."""

from dataclasses import dataclass

import numpy as np

from .material import linear_material, pemc_material
from ..section.law import rib_coverage

__all__ = ['SideView', 'side_view', 'LAW_NAMES']

#: The laws of a side view, in the order of `SideView.laws`.
LAW_NAMES = ('pemc', 'fluidic_layer', 'emc', 'constraining_layer')


@dataclass(frozen=True)
class SideView:
    """
    Cells of the finger's X-Z section over the free length, ready for `fe.Strip`.

    Attributes
    ----------
    x_breaks, z_breaks : ndarray
        Cell edges [m]: 0, every rib edge (ribs='exact'), the channel end, the free length;
        -H/2, -h3, -h3b, 0, h3a, h2, h1, H/2 (0 so that the midplane is a mesh line).
    cell_law : ndarray of int
        Index into `laws` (`LAW_NAMES`) of every cell.
    laws : tuple of BiotMaterial
    width, gas_width : ndarray
        Solid and gas width of every cell across Y [m].
    ribs : str
        'exact' or 'average'.
    at_rib : ndarray of bool
        Every column of cells (along X) that lies at a transverse rib (none with
        ribs='average').

    """

    x_breaks: np.ndarray
    z_breaks: np.ndarray
    cell_law: np.ndarray
    laws: tuple
    width: np.ndarray
    gas_width: np.ndarray
    ribs: str
    at_rib: np.ndarray


def _gas_widths(design, ribs):
    """Return the gas width between ribs and at a rib [m] (the section law's gas boxes)."""
    if not design.ribs:
        return design.Cy, design.Cy
    open_width = design.Cy - design.t
    rib_width = open_width - 2.0 * design.w1
    if ribs == 'average':
        smeared = open_width - 2.0 * design.w1 * rib_coverage(design)
        return smeared, smeared
    return open_width, rib_width


def layer_cells(design, breaks):
    """
    Return the layers' Z breaks and the law index (`LAW_NAMES`) of every cell.

    Parameters
    ----------
    design : ActuatorDesign
    breaks : array_like
        The cell edges along the other axis (X in the side view, Y in the cross-section)
        [m], sorted.

    Returns
    -------
    z_breaks : ndarray
        -H/2, -h3, -h3b, 0, h3a, h2, h1, H/2 [m] (0 so that the midplane is a mesh line).
    cell_law : ndarray of int, shape (len(breaks) - 1, len(z_breaks) - 1)

    """
    z_breaks = np.unique(np.round(np.array([-design.H / 2, -design.h3, -design.h3b, 0.0,
                                            design.h3a, design.h2, design.h1, design.H / 2]),
                                  12))
    zc = 0.5 * (z_breaks[1:] + z_breaks[:-1])
    law = np.select([zc < -design.h3, zc < design.h2, zc < design.h1], [0, 1, 2], 3)
    return z_breaks, np.broadcast_to(law, (len(breaks) - 1, zc.size)).copy()


def side_view(design, ribs='exact', poisson=False):
    """
    Build the cells of a design's side view.

    The channel band z in [-h3b, h3a], x in [0, channel end] is homogenised across the
    width: its solid part (Ly minus the gas width: side walls, longitudinal rib, and
    transverse ribs where they are) is the fluidic layer with that width, and its gas
    width carries the pressure. Everything else is solid across the full width Ly.

    Parameters
    ----------
    design : ActuatorDesign
    ribs : {'exact', 'average'}
        'exact' gives every transverse rib its own cells (gas width Cy - t - 2 w1);
        'average' smears them at their length coverage (`section.law.rib_coverage`).
    poisson : bool
        The linear laminae's X-Z Poisson coupling (`material.linear_material`).

    Returns
    -------
    SideView

    """
    if ribs not in ('exact', 'average'):
        raise ValueError(f"`ribs` must be 'exact' or 'average', got {ribs!r}")
    length, end = design.free_length, design.channel_end
    x = [0.0, end, length]
    rib_x = design.transverse_ribs() if ribs == 'exact' else np.zeros((0, 2))
    x.extend(rib_x.ravel())
    x_breaks = np.unique(np.round(np.array(x), 12))
    z_breaks, cell_law = layer_cells(design, x_breaks)
    xc = 0.5 * (x_breaks[1:] + x_breaks[:-1])
    zc = 0.5 * (z_breaks[1:] + z_breaks[:-1])
    open_gas, rib_gas = _gas_widths(design, ribs)
    at_rib = np.zeros(xc.size, dtype=bool)
    for lo, hi in rib_x:
        at_rib |= (xc > lo) & (xc < hi)
    band = (zc > -design.h3b) & (zc < design.h3a)
    channel = xc < end
    gas = np.where(at_rib, rib_gas, open_gas)[:, None] * (channel[:, None] & band[None, :])
    laws = (pemc_material(design.emc_coefficients, design.prestrain),
            linear_material(design.fluidic_layer, poisson=poisson),
            linear_material(design.emc, poisson=poisson),
            linear_material(design.constraining_layer, poisson=poisson))
    return SideView(x_breaks=x_breaks, z_breaks=z_breaks, cell_law=cell_law, laws=laws,
                    width=design.Ly - gas, gas_width=gas, ribs=ribs, at_rib=at_rib)
