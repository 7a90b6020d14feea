"""Hosts and sites on one machine: Linux network namespaces, and impairments of their links.

The hub namespace holds a bridge with the address SUBNET.1 (the coordinator's
host); every other namespace is a host (or a whole site) with one veth into that
bridge and the address SUBNET.(10+k). The namespaces have no default route:
traffic goes only between their own addresses. Needs root and iproute2 (``ip``):
:func:`unavailable` says why not. Namespaces are always deleted, also those left
by a killed earlier run (their name carries the pid).

Impairments of a host's link (its ``eth0``), each with the tool this machine has:

* delay: ``tc netem`` where the kernel has it, else :mod:`hysid.bench.relay`
  (a userspace TCP relay in the host's namespace that holds every byte);
* loss: ``tc netem loss`` where the kernel has it, else ``iptables -m statistic``
  (random drop of incoming and outgoing packets), else not applied (say why);
* cut and restore: ``ip link set eth0 down`` / ``up`` (always available).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field

from hysid.bench.relay import when_ready

SUBNET = "169.254.147"
"""Link-local /24 used only inside the namespaces."""
PREFIX = "hysidt"


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=check)


def unavailable() -> str | None:
    """Why network namespaces cannot be made here (None: they can, as far as can be told without trying)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "iproute2 'ip' is not installed"
    return None


class NamespacesUnavailable(RuntimeError):
    """This machine refused to make the namespaces (the message says which command and why)."""


def remove_stale_namespaces() -> None:
    """Delete namespaces of earlier runs whose process is gone (killed before its cleanup)."""
    for line in ip("netns", "list", check=False).stdout.splitlines():
        match = re.match(rf"({PREFIX}(\d+)-\S+)", line)
        if match and not os.path.exists(f"/proc/{match.group(2)}"):
            ip("netns", "del", match.group(1), check=False)


@dataclass
class Lab:
    """Network namespaces joined by a bridge in the hub's namespace."""

    hosts: int
    tag: str = field(default_factory=lambda: f"{PREFIX}{os.getpid()}")
    made: list[str] = field(default_factory=list)

    @property
    def hub(self) -> str:
        return f"{self.tag}-c"

    def host(self, k: int) -> str:
        return f"{self.tag}-h{k}"

    hub_address = f"{SUBNET}.1"

    @staticmethod
    def host_address(k: int) -> str:
        return f"{SUBNET}.{10 + k}"

    def _add(self, name: str) -> None:
        ip("netns", "add", name)
        self.made.append(name)
        ip("-n", name, "link", "set", "lo", "up")

    def build(self) -> None:
        """Make the namespaces; :class:`NamespacesUnavailable` where this machine refuses."""
        remove_stale_namespaces()
        try:
            self._build()
        except subprocess.CalledProcessError as exc:
            raise NamespacesUnavailable(f"cannot create network namespaces here: {' '.join(exc.cmd)}: {exc.stderr.strip()}") from None

    def _build(self) -> None:
        self._add(self.hub)
        ip("-n", self.hub, "link", "add", "br0", "type", "bridge")
        ip("-n", self.hub, "addr", "add", f"{self.hub_address}/24", "dev", "br0")
        ip("-n", self.hub, "link", "set", "br0", "up")
        for k in range(1, self.hosts + 1):
            self._add(self.host(k))
            port = f"veth{k}"
            ip("-n", self.hub, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", self.host(k))
            ip("-n", self.hub, "link", "set", port, "master", "br0", "up")
            ip("-n", self.host(k), "addr", "add", f"{self.host_address(k)}/24", "dev", "eth0")
            ip("-n", self.host(k), "link", "set", "eth0", "up")

    def destroy(self) -> None:
        for name in reversed(self.made):
            ip("netns", "del", name, check=False)
        self.made.clear()

    def namespaces(self) -> list[str]:
        return [self.hub, *(self.host(k) for k in range(1, self.hosts + 1))]

    def command(self, namespace: str, *argv: str) -> list[str]:
        return ["ip", "netns", "exec", namespace, *argv]

    # impairments of host k's link

    def has_netem(self) -> bool:
        """Whether this kernel has the netem qdisc (tried on the hub's loopback, then removed)."""
        added = (
            subprocess.run(["tc", "-n", self.hub, "qdisc", "add", "dev", "lo", "root", "netem", "delay", "0ms"], capture_output=True, timeout=20)
            if shutil.which("tc")
            else None
        )
        if added is None or added.returncode != 0:
            return False
        subprocess.run(["tc", "-n", self.hub, "qdisc", "del", "dev", "lo", "root"], capture_output=True, timeout=20)
        return True

    def netem(self, k: int, delay_ms: float, loss_pct: float) -> None:
        """Delay and loss each way on host k's link with netem (needs :meth:`has_netem`)."""
        for namespace, device in ((self.host(k), "eth0"), (self.hub, f"veth{k}")):
            subprocess.run(
                ["tc", "-n", namespace, "qdisc", "add", "dev", device, "root", "netem", "delay", f"{delay_ms:g}ms", "loss", f"{loss_pct:g}%"],
                check=True,
                capture_output=True,
                timeout=20,
            )

    def drop(self, k: int, loss_pct: float) -> str | None:
        """Randomly drop ``loss_pct`` % of host k's incoming and outgoing packets with iptables;
        the reason it cannot (None: applied)."""
        if shutil.which("iptables") is None:
            return "iptables is not installed"
        for chain, side in (("INPUT", "-i"), ("OUTPUT", "-o")):
            done = subprocess.run(
                self.command(
                    self.host(k),
                    "iptables",
                    "-A",
                    chain,
                    side,
                    "eth0",
                    "-m",
                    "statistic",
                    "--mode",
                    "random",
                    "--probability",
                    f"{loss_pct / 100:g}",
                    "-j",
                    "DROP",
                ),
                capture_output=True,
                text=True,
                timeout=20,
            )
            if done.returncode != 0:
                return f"iptables statistic match refused: {done.stderr.strip()}"
        return None

    def delay_relay(self, k: int, port: int, upstream_port: int, delay_ms: float) -> subprocess.Popen:
        """A :mod:`hysid.bench.relay` in host k's namespace: ``127.0.0.1:port`` reaches the hub's
        ``upstream_port`` over host k's link with ``delay_ms`` more each way; returns once it listens."""
        relay = subprocess.Popen(
            self.command(
                self.host(k), sys.executable, "-m", "hysid.bench.relay", "127.0.0.1", str(port), self.hub_address, str(upstream_port), f"{delay_ms:g}"
            ),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        return when_ready(relay, lambda p: f"delay relay in {self.host(k)} did not start: {p.communicate()[1].strip()}")

    def link(self, k: int, up: bool) -> None:
        """Cut (``up=False``) or restore host k's link."""
        ip("-n", self.host(k), "link", "set", "eth0", "up" if up else "down")
