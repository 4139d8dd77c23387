"""The MCAP event log: write, read, fold into state, re-publish, verify."""
