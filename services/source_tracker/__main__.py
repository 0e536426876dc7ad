from services.source_tracker.tracker import main

main()
