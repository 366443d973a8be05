"""Outputs for other tools: glTF binary scenes (:mod:`.gltf`) and Rerun recordings
(:mod:`.rerun_log`, optional extra ``rerun``).

Nothing here is imported by ``import monoplane``; :func:`monoplane.log_rerun` loads
:mod:`.rerun_log` on first use.
"""
