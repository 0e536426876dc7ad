"""The source operator's tracker: filters its own sensor, publishes only its estimate (to the
referee) and the transfer (eta_hat_{k+1}, P_eta_eta,k+1) for the primary."""
