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


def rule(rule_id: str, messages: list[str], keys: list[str], flow: str = "ingress") -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": keys}


def access_control(campaign: str, islands: list[str]) -> dict:
    """Deny by default; each island's own keys for the subject with its certificate CN and user name."""
    p = f"hysid/{campaign}"
    shared = [
        rule("listen", ["declare_subscriber"], [f"{p}/migrants/*", f"{p}/control", f"{p}/best"]),
        rule("ask", ["query"], [f"{p}/config", f"{p}/best"]),
        rule("deliver", ["put", "delete", "declare_subscriber", "declare_queryable", "query", "reply",
                         "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"], [f"{p}/**"], "egress"),
        rule("see-members", ["declare_liveliness_subscriber", "liveliness_query"], [f"{p}/members/*"]),
    ]
    rules, subjects, policies = list(shared), [], []
    for island in islands:
        own = [
            rule(f"{island}-publish", ["put"], [f"{p}/migrants/{island}", f"{p}/history/{island}"]),
            rule(f"{island}-join", ["query"], [f"{p}/join/{island}"]),
            rule(f"{island}-serve", ["declare_queryable", "reply"], [f"{p}/history/{island}"]),
            rule(f"{island}-token", ["liveliness_token"], [f"{p}/members/{island}"]),
        ]
        rules += own
        subjects.append({"id": island, "cert_common_names": [island], "usernames": [island]})
        policies.append({"rules": [r["id"] for r in shared + own], "subjects": [island]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def coordinator_config(campaign: str, listen: str, certs: str, credentials: str, islands: list[str]) -> dict:
    return {
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": [listen.split("/")[0]],
                "tx": LEASE,
                "tls": {
                    "root_ca_certificate": f"{certs}/ca.pem",
                    "listen_certificate": f"{certs}/coordinator/cert.pem",
                    "listen_private_key": f"{certs}/coordinator/key.pem",
                    "enable_mtls": True,
                    "close_link_on_expiration": True,
                },
            },
            "auth": {"usrpwd": {"dictionary_file": credentials}},
        },
        "access_control": access_control(campaign, islands),
    }


def island_config(island: str, connect: str, certs: str, password: str) -> dict:
    return {
        "mode": "client",
        "connect": {"endpoints": [connect], "timeout_ms": 60000, "exit_on_failure": True,
                    "retry": {"period_init_ms": 250, "period_max_ms": 2000, "period_increase_factor": 2}},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": [connect.split("/")[0]],
                "tx": LEASE,
                "tls": {
                    "root_ca_certificate": f"{certs}/ca.pem",
                    "connect_certificate": f"{certs}/islands/{island}/cert.pem",
                    "connect_private_key": f"{certs}/islands/{island}/key.pem",
                    "enable_mtls": True,
                    "verify_name_on_connect": True,
                    "close_link_on_expiration": True,
                },
            },
            "auth": {"usrpwd": {"user": island, "password": password}},
        },
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
    parser.add_argument("islands", nargs="+", help="island ids (each needs a certificate with CN=<id>)")
    args = parser.parse_args(argv)
    problems = [f"--campaign {args.campaign!r}" for _ in [0] if not NAME.match(args.campaign)]
    problems += [f"island id {i!r}" for i in args.islands if not NAME.match(i)]
    problems += [f"{flag} {value!r} (use tls/HOST:PORT)" for flag, value in (("--listen", args.listen), ("--connect", args.connect)) if not ENDPOINT.match(value)]
    if len(set(args.islands)) != len(args.islands):
        problems.append("island ids repeat")
    if problems:
        print(f"secure-campaign.py: error: invalid {'; '.join(problems)}", file=sys.stderr)
        return 2
    out = args.outdir
    (out / "islands").mkdir(parents=True, exist_ok=True, mode=0o700)
    out.chmod(0o700)
    credentials = args.credentials or str((out / "credentials.txt").resolve())
    passwords = {island: secrets.token_urlsafe(24) for island in args.islands}
    write_private(out / "credentials.txt", "".join(f"{i}:{pw}\n" for i, pw in passwords.items()))
    coordinator = coordinator_config(args.campaign, args.listen, args.certs, credentials, args.islands)
    write_private(out / "coordinator.json5", HEADER.format(campaign=args.campaign, what="the coordinator") + json.dumps(coordinator, indent=2) + "\n")
    for island, password in passwords.items():
        text = HEADER.format(campaign=args.campaign, what=f"island {island}") + json.dumps(island_config(island, args.connect, args.certs, password), indent=2)
        write_private(out / "islands" / f"{island}.json5", text + "\n")
    print(f"wrote {out}/coordinator.json5, credentials.txt and islands/<id>.json5 for {len(args.islands)} islands of campaign {args.campaign!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
