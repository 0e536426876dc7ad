"""Batch work runs below the live stacks' priority.

``make test`` runs the live tests (whose steps have deadlines of tens of milliseconds) beside
CPU-bound batch work: the golden trees' experiments, the site's build, the image's wheels. On two
cores a live service then waits for the CPU past its deadline now and then, and a step goes
isolated that should not. Started through :data:`BELOW`, the batch work yields the CPU to them;
it takes as long as before when nothing else runs.
"""

#: prefix of a batch command: niceness 5 (the live stacks run at 0), a third of their CPU weight.
#: At 10 (a tenth), two CPU-bound processes beside make test starved the site's build (828 s).
BELOW = ["nice", "-n", "5"]
