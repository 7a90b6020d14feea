"""Write the Zenoh configurations of one campaign over an untrusted network: TLS with mutual
authentication, a user name and password per island, and an access-control list that binds each
island's keys to its authenticated identity.

    python deploy/secure-campaign.py --campaign demo --listen tls/10.1.0.11:7447 --connect tls/node01:7447 \\
        --certs /etc/hysid/tls -o /etc/hysid/zenoh island-1 island-2 island-3

writes, in the output directory (mode 700, files 600):

* ``coordinator.json5``: a router listening on the endpoint you name (never all interfaces
  unless you say so with ``--listen tls/0.0.0.0:PORT``), mTLS, the credentials file, and an ACL
  (deny by default) in which island ``X`` is the connection whose certificate has ``CN=X``
  *and* whose user name is ``X``; it may publish only ``migrants/X`` and ``history/X``, join only
  as ``join/X``, serve only ``history/X`` and hold only the token ``members/X``, all under
  ``hysid/<campaign>/``. It cannot speak for another island, forge the coordinator's control or
  best, or see another campaign;
* ``credentials.txt``: ``island:password`` lines, fresh random passwords: campaigns that share a
  CA and island names still do not share passwords;
* ``islands/<island>.json5``: each island's client config (its certificate, user and password).

A process of many islands (``hysid island --id node7 --count 64``: islands ``node7-0`` ..
``node7-63`` over one connection) is named ``node7:64``: one identity (certificate CN, user and
config ``node7``) that may speak for exactly those islands' keys, and for no other.

The certificates come from ``deploy/tls/make-certs.sh`` (CN = island id); ``--certs`` is the
directory it wrote, as the machines will see it. Secrets stay in these files: nothing is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import secrets
import sys
from pathlib import Path

NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")
ENDPOINT = re.compile(r"(tls|quic)/\S+:\d{1,5}\Z")
LEASE = {"lease": 2000, "keep_alive": 4}
MAX_COUNT = 4096
"""Islands one process may run (hysid island --count)."""


def rule(rule_id: str, messages: list[str], keys: list[str], flow: str = "ingress") -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": keys}


def hosted_islands(host: str, count: int) -> list[str]:
    """The islands of ``hysid island --id host --count count`` (as island/host.py names them)."""
    return [host] if count == 1 else [f"{host}-{k}" for k in range(count)]


def access_control(campaign: str, hosts: dict[str, list[str]]) -> dict:
    """Deny by default; each host's islands' own keys for the subject with the host's certificate CN and user name."""
    p = f"hysid/{campaign}"
    shared = [
        rule("listen", ["declare_subscriber"], [f"{p}/migrants/*", f"{p}/control", f"{p}/best"]),
        rule("ask", ["query"], [f"{p}/config", f"{p}/best"]),
        rule(
            "deliver",
            [
                "put",
                "delete",
                "declare_subscriber",
                "declare_queryable",
                "query",
                "reply",
                "liveliness_token",
                "declare_liveliness_subscriber",
                "liveliness_query",
            ],
            [f"{p}/**"],
            "egress",
        ),
        rule("see-members", ["declare_liveliness_subscriber", "liveliness_query"], [f"{p}/members/*"]),
    ]
    rules, subjects, policies = list(shared), [], []
    for host, islands in hosts.items():
        own = []
        for island in islands:
            own += [
                rule(f"{island}-publish", ["put"], [f"{p}/migrants/{island}", f"{p}/history/{island}"]),
                rule(f"{island}-join", ["query"], [f"{p}/join/{island}"]),
                rule(f"{island}-serve", ["declare_queryable", "reply"], [f"{p}/history/{island}"]),
                rule(f"{island}-token", ["liveliness_token"], [f"{p}/members/{island}"]),
            ]
        rules += own
        subjects.append({"id": host, "cert_common_names": [host], "usernames": [host]})
        policies.append({"rules": [r["id"] for r in shared + own], "subjects": [host]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def transport(endpoint: str, certs: str, files: dict, usrpwd: dict, verify_name: bool = False) -> dict:
    """The ``transport`` section of either side: the endpoint's protocol, the lease, mutual TLS under the campaign's CA
    with this side's certificate and key ``files`` (the connecting side checking the name, ``verify_name``), and
    user/password authentication ``usrpwd``."""
    tls = {"root_ca_certificate": f"{certs}/ca.pem", **files, "enable_mtls": True}
    if verify_name:
        tls["verify_name_on_connect"] = True
    tls["close_link_on_expiration"] = True
    return {"link": {"protocols": [endpoint.split("/")[0]], "tx": LEASE, "tls": tls}, "auth": {"usrpwd": usrpwd}}


def coordinator_config(campaign: str, listen: str, certs: str, credentials: str, hosts: dict[str, list[str]]) -> dict:
    return {
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": transport(
            listen,
            certs,
            {"listen_certificate": f"{certs}/coordinator/cert.pem", "listen_private_key": f"{certs}/coordinator/key.pem"},
            {"dictionary_file": credentials},
        ),
        "access_control": access_control(campaign, hosts),
    }


def island_config(island: str, connect: str, certs: str, password: str) -> dict:
    return {
        "mode": "client",
        "connect": {
            "endpoints": [connect],
            "timeout_ms": 60000,
            "exit_on_failure": True,
            "retry": {"period_init_ms": 250, "period_max_ms": 2000, "period_increase_factor": 2},
        },
        "scouting": {"multicast": {"enabled": False}},
        "transport": transport(
            connect,
            certs,
            {"connect_certificate": f"{certs}/islands/{island}/cert.pem", "connect_private_key": f"{certs}/islands/{island}/key.pem"},
            {"user": island, "password": password},
            verify_name=True,
        ),
    }


HEADER = """// Written by deploy/secure-campaign.py for campaign {campaign!r} ({what}); edit by running it again.
// TLS with mutual authentication, user/password, and (coordinator) an access-control list binding
// each island's keys to the certificate CN and user name of that island. See deploy/GUIDE.md.
"""


def write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaign", required=True, help="campaign name (the key space hysid/<campaign>/**)")
    parser.add_argument("--listen", required=True, help="the coordinator's endpoint on the interface islands reach, e.g. tls/10.1.0.11:7447")
    parser.add_argument("--connect", required=True, help="the endpoint islands dial, e.g. tls/node01:7447 (a name in the coordinator certificate)")
    parser.add_argument("--certs", required=True, help="the make-certs.sh directory, as the machines see it")
    parser.add_argument("--credentials", help="where the coordinator reads credentials.txt (default: OUTDIR/credentials.txt)")
    parser.add_argument("-o", "--outdir", required=True, type=Path)
    parser.add_argument(
        "islands",
        nargs="+",
        help="island ids (each needs a certificate with CN=<id>), or ID:COUNT for a process of "
        "COUNT islands ID-0 .. ID-<COUNT-1> (hysid island --id ID --count COUNT; the certificate CN=ID)",
    )
    args = parser.parse_args(argv)
    problems = [f"--campaign {args.campaign!r}" for _ in [0] if not NAME.match(args.campaign)]
    given = [(host, count) for host, _, count in (i.partition(":") for i in args.islands)]
    problems += [
        f"island id {h + (':' if c else '') + c!r}" + (f" (ID:COUNT, COUNT from 1 to {MAX_COUNT})" if c else "")
        for h, c in given
        if not NAME.match(h) or (c and not (c.isdigit() and 1 <= int(c) <= MAX_COUNT))
    ]
    hosts = {h: hosted_islands(h, int(c or 1)) for h, c in given if not problems}
    every = [i for islands in hosts.values() for i in islands]
    problems += [f"island id {i!r}" for i in every if not NAME.match(i)]
    problems += [
        f"{flag} {value!r} (use tls/HOST:PORT)" for flag, value in (("--listen", args.listen), ("--connect", args.connect)) if not ENDPOINT.match(value)
    ]
    if (len(hosts) != len(given) and hosts) or len(set(every)) != len(every):
        problems.append("island ids repeat")
    if problems:
        print(f"secure-campaign.py: error: invalid {'; '.join(problems)}", file=sys.stderr)
        return 2
    out = args.outdir
    (out / "islands").mkdir(parents=True, exist_ok=True, mode=0o700)
    out.chmod(0o700)
    credentials = args.credentials or str((out / "credentials.txt").resolve())
    passwords = {host: secrets.token_urlsafe(24) for host in hosts}
    write_private(out / "credentials.txt", "".join(f"{i}:{pw}\n" for i, pw in passwords.items()))
    coordinator = coordinator_config(args.campaign, args.listen, args.certs, credentials, hosts)
    write_private(out / "coordinator.json5", HEADER.format(campaign=args.campaign, what="the coordinator") + json.dumps(coordinator, indent=2) + "\n")
    for island, password in passwords.items():
        text = HEADER.format(campaign=args.campaign, what=f"island {island}") + json.dumps(island_config(island, args.connect, args.certs, password), indent=2)
        write_private(out / "islands" / f"{island}.json5", text + "\n")
    print(
        f"wrote {out}/coordinator.json5, credentials.txt and islands/<id>.json5 for {len(every)} islands of campaign {args.campaign!r}"
        + (f" in {len(hosts)} processes" if len(hosts) != len(every) else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
