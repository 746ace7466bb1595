"""The commands that read run folders (``remidi run``'s outputs): ``status``, ``table``,
``compare``, ``evaluate`` and ``render``, one module each."""
