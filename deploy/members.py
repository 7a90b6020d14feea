"""List the islands currently in a hysid campaign: the liveliness tokens hysid/<campaign>/members/*.

    python deploy/members.py --connect tcp/HOST:7447 --campaign NAME [--config island.json5]

It joins as a Zenoh client, like an island (same --config, so it also works
through TLS, user/password and the access-control list of deploy/zenoh), asks
which members are alive, prints one island id per line and exits: status 0
when at least one member is alive, 1 when none, 2 on a bad argument or when the
coordinator cannot be reached. An island that froze or lost its network drops
out within the lease of its Zenoh config (2 s with deploy/zenoh).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hysid_model.errors import HysidInputError
from island.joining import key_prefix
from island.session import open_session, session_config


def live_members(connect: list[str], config_file: Path | None, campaign: str, timeout_s: float) -> list[str]:
    """Island ids with a liveliness token under hysid/<campaign>/members/."""
    prefix = key_prefix(campaign)
    config = session_config("client", connect=connect, config_file=config_file, connect_timeout_s=timeout_s)
    session = open_session(config, f"connect {', '.join(connect) or f'as in {config_file}'}")
    try:
        replies = session.liveliness().get(f"{prefix}/members/*", timeout=timeout_s)
        return sorted({str(reply.ok.key_expr).rsplit("/", 1)[-1] for reply in replies if reply.ok is not None})
    finally:
        session.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--connect", action="append", default=[], help="coordinator endpoint, e.g. tcp/HOST:7447 (repeatable)")
    parser.add_argument("--config", type=Path, default=None, help="Zenoh client config, e.g. deploy/zenoh/island.json5")
    parser.add_argument("--campaign", required=True, help="campaign name")
    parser.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the coordinator and the answers")
    args = parser.parse_args(argv)
    if not args.connect and args.config is None:
        parser.error("give --connect ENDPOINT and/or --config FILE")
    try:
        members = live_members(args.connect, args.config, args.campaign, args.timeout)
    except HysidInputError as exc:
        print(f"members.py: error: {exc}", file=sys.stderr)
        return 2
    print("\n".join(members) if members else f"no island is a member of campaign {args.campaign!r}", file=sys.stdout if members else sys.stderr)
    return 0 if members else 1


if __name__ == "__main__":
    sys.exit(main())
