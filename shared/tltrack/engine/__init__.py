"""Scenarios, random streams, the Monte-Carlo engine and the PCRLB."""
