"""The Python API behind `import swarm` (swarm/__init__.py exports its names): finished runs
(`runs`), scenarios (`scenario`), `swarm.launch` (`launch`), `swarm.up` (`up`), live runs
(`live`) and the records they return (`record`)."""
