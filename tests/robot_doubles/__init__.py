"""Protocol test doubles of the robot side: an IrisTK broker, a Furhat on it, a Realtime API server."""
