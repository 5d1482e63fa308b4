"""The composition format: YAML with locations, the typed description, layers (`extends:`), the
flag and LCSM vocabulary, the composition graph every check runs on, and the JSON Schema."""
