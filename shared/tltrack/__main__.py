from tltrack.cli import app

app()
