"""C-DOG, the method: the words its stages declare their options in (``_config``), the options
table derived from them (``_options``), what the stages share (``_stage``) and the method
itself: ``Config``, its presets, the stage list and the plan runner (``_pipeline``). The
stages live in ``graph/`` and ``refine/``."""
