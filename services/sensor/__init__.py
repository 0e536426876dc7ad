"""One operator's sensor: measures on the referee's clock and publishes on its owner's key, so
its raw data enters the network at its owner's router and nowhere else."""
