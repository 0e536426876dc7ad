from tltrack.services.sensor.sensor import main

main()
