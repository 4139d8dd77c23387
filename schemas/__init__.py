"""The contract: msgspec Structs for every event, config and file format."""
