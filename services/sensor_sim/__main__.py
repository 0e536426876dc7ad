from tltrack.services.sensor_sim.simulator import main

main()
