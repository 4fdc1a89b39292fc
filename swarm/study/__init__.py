"""`swarm study`: batch studies of random swarms (`swarms`) and of gains (`gains`), run on a
process pool (`pool`) or the batch engine (`batch`), with their figures (`figures`)."""
