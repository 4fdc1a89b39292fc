"""`swarm study`: batch studies of random swarms (`swarms`), of gains (`gains`) and of one's own
scenario (`scenario`, with `vectorised` for laws the batch engine runs), run on a
process pool (`pool`) or the batch engine (`batch`), with their figures (`figures`)."""
