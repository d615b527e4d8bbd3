"""The interface every pressure-regulator backend implements."""

import dataclasses
import math
import typing


class BackendFault(RuntimeError):
    """
    The regulator cannot be reached or refused a request.

    Raised by :class:`RegulatorBackend` methods at run time (link down, device
    error, not connected). Bad arguments raise ValueError or TypeError instead.
    """


@dataclasses.dataclass(frozen=True)
class BackendStatus:
    """
    Health of a backend, as returned by :meth:`RegulatorBackend.status`.

    Attributes
    ----------
    ok : bool
        True when the backend is connected and reports no fault.
    fault : str or None
        Why the backend is not ok (None when ``ok``).
    connected : bool
        True between a successful ``connect()`` and ``close()``.
    n_channels : int
        Number of pressure channels.
    """

    ok: bool
    fault: typing.Optional[str] = None
    connected: bool = False
    n_channels: int = 0


@typing.runtime_checkable
class RegulatorBackend(typing.Protocol):
    """
    A multi-channel pressure regulator.

    Every pressure at this interface is GAUGE pressure in pascals. Channels are
    numbered ``0 .. n_channels - 1``. Methods other than :meth:`status` and
    :meth:`close` raise :class:`BackendFault` when the device cannot serve them;
    :meth:`status` never raises.
    """

    n_channels: int

    def connect(self) -> None:
        """
        Open the link to the device; calling it again while connected is a no-op.

        Raises
        ------
        BackendFault
            If the device cannot be reached.
        """

    def close(self) -> None:
        """Close the link; safe to call more than once."""

    def set_pressure(self, channel: int, pressure_pa_gauge: float) -> None:
        """
        Command the output pressure of one channel.

        Parameters
        ----------
        channel : int
            Channel index.
        pressure_pa_gauge : float
            Setpoint [Pa gauge]. Values outside the device's range saturate.
        """

    def read_pressure(self, channel: int) -> typing.Tuple[float, float]:
        """
        Read the measured output pressure of one channel.

        Returns
        -------
        value : float
            Measured pressure [Pa gauge].
        variance : float
            Variance of the measurement [Pa²].
        """

    def status(self) -> BackendStatus:
        """Return the current health without raising."""


def check_channel(channel, n_channels):
    """
    Return ``channel`` as an int after checking it indexes one of ``n_channels``.

    Raises
    ------
    TypeError
        If ``channel`` is not an integer.
    ValueError
        If ``channel`` is out of range.
    """
    if isinstance(channel, bool) or not hasattr(channel, '__index__'):
        raise TypeError(f'`channel` must be an int, got {channel!r}')
    index = int(channel)
    if not 0 <= index < n_channels:
        raise ValueError(f'`channel` must be in [0, {n_channels - 1}], got {index}')
    return index


def check_pressure(pressure_pa_gauge):
    """
    Return ``pressure_pa_gauge`` as a float after checking it is finite.

    Raises
    ------
    ValueError
        If the value is NaN or infinite.
    """
    value = float(pressure_pa_gauge)
    if not math.isfinite(value):
        raise ValueError(f'`pressure_pa_gauge` must be finite [Pa], got {value}')
    return value
