from tltrack.app.cli import app

app()
