"""coordinator: the campaign coordinator (loop set service, membership, stop rules), its SQLite store,
its links to the islands, and the launcher of a campaign on one machine."""
