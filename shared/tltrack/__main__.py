from tltrack.app import app

app()
