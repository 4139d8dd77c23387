from pairplay.cli.main import entry

entry()
