"""The brain: sensor, perception, behaviour selection, memory and motor modules (Fig. 1)."""
