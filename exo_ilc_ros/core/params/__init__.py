"""The parameters, one schema for all (YAML, ROS parameters, validation, bags' provenance): the
schema and its rules, the config, the checks of every message and live update. The bottom room:
it imports no other."""
