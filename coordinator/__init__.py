"""coordinator: campaigns (loop set service, membership, SQLite histories) and the ``hysid`` CLI."""
