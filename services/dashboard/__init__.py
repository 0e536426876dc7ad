"""The live dashboard: a read-only referee that draws the episode in a browser and exports metrics.

It subscribes to the truth, every estimate, the liveliness tokens and the services' statistics,
keeps the last few episodes in memory, and serves (FastAPI + uvicorn) a page that polls a JSON
snapshot, plus ``/metrics`` for Prometheus. It publishes nothing but its own statistics.
"""
