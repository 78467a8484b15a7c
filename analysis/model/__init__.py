"""The physical model of a trial: the rig file, the rudder-stock-hull structure, its exact
response to a ram blow, the sensors and front-end, gage geometry and the report's units."""
