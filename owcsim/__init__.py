"""The `owcsim` command line: composes schemas, engine (and later server, clients)."""
