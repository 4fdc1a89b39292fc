"""The contracts of a run, the floor every other package stands on: scenario files
(`scenario`), follower-law names (`laws`), sensor frames (`frames`), the wire format
(`wire`), what an agent is told when it joins (`brain_config`) and the zenoh settings
(`transport`). They import nothing from `agents`, `world` or the rest of `swarm`
(tests/pure/test_layers.py checks it)."""
