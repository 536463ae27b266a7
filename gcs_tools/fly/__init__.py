"""``beliefnav fly``: one mission flown in-process (the loop: ``simvehicle.harness.fly``); CLI and files."""
