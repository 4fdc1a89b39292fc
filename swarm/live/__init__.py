"""A live run seen from any terminal: find it and query it (`client`), what the live commands
show as plain data (`data`), acting on agents (`control`), how it looks (`views`, `watch`: pure
functions) and the Foxglove observer (`foxglove`)."""
