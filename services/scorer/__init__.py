"""The referee: records the truth and every estimate in SQLite and reports RMSE and latency."""
