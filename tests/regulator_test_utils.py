"""Test doubles of the regulator tests: a hand-driven clock and a pymodbus server on loopback."""

import asyncio
import threading


class FakeClock:
    """A clock the test advances by hand [s]."""

    def __init__(self, start=100.0):
        self.now = start

    def __call__(self):
        return self.now


class Server:
    """
    A pymodbus TCP server in its own thread and event loop (unit 1, 32 + 32 registers).

    ``action`` is pymodbus's SimDevice hook, called on every register access: it may
    rewrite the registers or return an exception code. `stop` and `start` close and
    reopen the server on the same port (a device that drops off the network).
    """

    def __init__(self, action=None):
        self.action = action
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server = None
        self.port = 0
        self.start()

    def start(self):
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType
        from pymodbus.simulator import SimData
        from pymodbus.simulator import SimDevice

        def bits():
            return [SimData(0, count=16, values=False, datatype=DataType.BITS)]

        def words():
            return [SimData(0, count=32, values=0, datatype=DataType.REGISTERS)]

        async def start():
            device = SimDevice(1, simdata=(bits(), bits(), words(), words()),
                               action=self.action)
            server = ModbusTcpServer(device, address=('127.0.0.1', self.port))
            await server.serve_forever(background=True)
            return server

        self.server = self.call(start())
        self.port = self.server.transport.sockets[0].getsockname()[1]

    def call(self, coroutine):
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout=5)

    def get(self, function_code, address):
        return self.call(self.server.async_getValues(1, function_code, address, 1))[0]

    def put(self, function_code, address, value):
        self.call(self.server.async_setValues(1, function_code, address, [value]))

    def stop(self):
        """Close the server and every connection to it; the port stays this server's."""
        self.call(self.server.shutdown())

    def close(self):
        self.stop()
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)
