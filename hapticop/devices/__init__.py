"""Device libraries (protocols, kinematics, controllers, simulators) the device blocks build on."""
