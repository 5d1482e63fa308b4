"""Generic blocks: device drivers, controllers and the application mediator.

Each block declares its ports, flags, parameters and rates (see `interface`); the
composition file instantiates blocks as activities and wires them.
"""
