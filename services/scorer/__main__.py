from tltrack.services.scorer.scorer import main

main()
