"""The console's headless core: operator session, arm state, grasp session, table scene."""
