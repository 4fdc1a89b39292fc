"""Running a swarm as processes: the launcher of `swarm up` (`launcher`), what it makes of a
child that exits (`supervision`), process groups and deadlines (`procs`), the agents' fork
server client (`forks`), agent hosts on other machines (`host`, `host_setup`) and the progress
line (`progress`). Imports the contracts only."""
