from services.primary_tracker.tracker import main

main()
