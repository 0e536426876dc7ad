from tltrack.services.dashboard.server import main

main()
