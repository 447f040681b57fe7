"""One module per studio tab: ``files``, ``creature``, ``motion``, ``tree``, ``leaf``."""
