from tltrack.services.source_tracker.tracker import main

main()
