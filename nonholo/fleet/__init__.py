"""nonholo.fleet: every robot its own program (thesis §2.6, §5.2; spec fleet.md).

Layers, each importing only those above it::

    step      compiled per-robot steps: the kernel's own command and RK4 functions
    setup     what one robot needs from a scenario (its law, parents, plan, tables)
    plant     the plant interface (read pose, command v and ω) and the simulated unicycle
    messages  the robot-state content of the ``leader-follower-v1`` ontology
    links     a robot's authenticated links to its parents and children (comm layers)
    robot     the robot program: subscribe, control loop, publish
    launch    start every robot of a scenario and gather one result
"""
