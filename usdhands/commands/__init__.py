"""One module per ``usdhands`` subcommand; each defines ``register(subparsers)``."""
