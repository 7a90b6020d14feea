"""A TCP relay that delays every byte by a fixed time: a WAN link's latency where ``tc netem`` is missing.

``python -m hysid.bench.relay LISTEN_HOST LISTEN_PORT UPSTREAM_HOST UPSTREAM_PORT DELAY_MS``
accepts connections on LISTEN, opens one connection to UPSTREAM for each, and
forwards both directions, each chunk held DELAY_MS after it was read (order kept,
throughput not limited, as netem's ``delay`` on a fast link). It prints ``ready``
once listening. A failed upstream connection closes the accepted one (the dialler
retries, as over a dead link); a connection closed on either side closes the other.
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from collections.abc import Callable


def when_ready(process: subprocess.Popen, failure: Callable[[subprocess.Popen], str]) -> subprocess.Popen:
    """``process`` once its first line on stdout is ``ready`` (as the relay and :func:`hysid.bench.processes.flooder`
    print it); else it is killed and a RuntimeError says ``failure(process)``."""
    assert process.stdout is not None
    if process.stdout.readline().strip() != "ready":
        process.kill()
        raise RuntimeError(failure(process))
    return process


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter, delay_s: float) -> None:
    held: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()

    async def deliver() -> None:
        while True:
            due, chunk = await held.get()
            if not chunk:
                break
            await asyncio.sleep(max(0.0, due - time.monotonic()))
            writer.write(chunk)
            await writer.drain()

    sender = asyncio.create_task(deliver())
    try:
        while chunk := await reader.read(65536):
            held.put_nowait((time.monotonic() + delay_s, chunk))
    except ConnectionError:
        pass
    held.put_nowait((0.0, b""))
    try:
        await sender
    except ConnectionError:
        pass
    writer.close()


async def _serve(listen: tuple[str, int], upstream: tuple[str, int], delay_s: float) -> None:
    async def connection(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.wait_for(asyncio.open_connection(*upstream), timeout=5.0)
        except (TimeoutError, OSError):
            writer.close()
            return
        pipes = {asyncio.create_task(_pipe(reader, up_writer, delay_s)), asyncio.create_task(_pipe(up_reader, writer, delay_s))}
        _, pending = await asyncio.wait(pipes, return_when=asyncio.FIRST_COMPLETED)
        for pipe in pending:  # the other direction may hang on a dead link: drop it
            pipe.cancel()
        for side in (writer, up_writer):
            side.transport.abort()

    server = await asyncio.start_server(connection, *listen)
    print("ready", flush=True)
    async with server:
        await server.serve_forever()


def main(argv: list[str]) -> None:
    listen_host, listen_port, upstream_host, upstream_port, delay_ms = argv
    asyncio.run(_serve((listen_host, int(listen_port)), (upstream_host, int(upstream_port)), float(delay_ms) / 1000.0))


if __name__ == "__main__":
    main(sys.argv[1:])
