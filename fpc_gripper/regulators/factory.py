"""Build a pressure-regulator backend by name."""

from fpc_gripper.regulators.modbus import ModbusRegulator
from fpc_gripper.regulators.sim import SimulatedRegulator

BACKEND_KINDS = ('sim', 'modbus')


def make_backend(kind, **params):
    """
    Build an (unconnected) regulator backend.

    Parameters
    ----------
    kind : {'sim', 'modbus'}
        'sim' builds a :class:`~fpc_gripper.regulators.sim.SimulatedRegulator`
        (``params``: n_channels, time_constant_s, slew_rate_pa_s, deadband_pa,
        max_output_pa, adc_bits, full_scale_pa, noise_std_pa, seed, clock);
        'modbus' builds a :class:`~fpc_gripper.regulators.modbus.ModbusRegulator`
        (``params``: register_map (a RegisterMap or a YAML path), host, port,
        device_id, timeout_s, reconnect_interval_s, clock).
    **params
        Passed to the backend's constructor.

    Returns
    -------
    RegulatorBackend

    Raises
    ------
    ValueError
        If ``kind`` is unknown (the message lists the valid kinds) or a parameter
        is out of range.
    """
    if kind == 'sim':
        return SimulatedRegulator(**params)
    if kind == 'modbus':
        return ModbusRegulator(**params)
    raise ValueError(f'`kind` must be one of {list(BACKEND_KINDS)}, got {kind!r}')
