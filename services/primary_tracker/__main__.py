from tltrack.services.primary_tracker.tracker import main

main()
