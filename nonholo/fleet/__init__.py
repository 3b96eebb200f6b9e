"""nonholo.fleet: every robot its own program (thesis §2.6, §5.2; spec fleet.md).

Layers, each importing only those above it::

    step      compiled per-robot steps: the kernel's own command and RK4 functions
    setup     what one robot needs from a scenario (its law, parents, plan, tables)
    plant     the plant interface (read pose, command v and ω) and the simulated unicycles
    messages  the robot-state content of the ``leader-follower-v1`` ontology
    config    the scenario's ``[network]`` table

The link model (one seeded draw of delays and losses) and the follower's watchdog (a pure
state machine) live a layer below, in ``nonholo.sim.links`` and ``nonholo.sim.watchdog``:
the centralized simulator applies them too, so that ``nonholo run`` predicts a lockstep run.
    keys      a fleet's keys (one per robot) and a robot's secure channel
    mesh      a robot's authenticated TCP links to its parents and children (comm layers)
    robot     the robot program: subscribe, control loop (lockstep, realtime), publish
    telemetry a robot's status streamed to an observer (a live view), and its endpoint
    process   one robot program as its own OS process (``nonholo robot``)
    spawn     one process per robot, every process reaped
    report    the link-health figure and the network table
    launch    start every robot of a scenario and gather one result
    bench     fleet figures (``nonholo bench-fleet``)
"""
