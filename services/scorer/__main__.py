from services.scorer.scorer import main

main()
