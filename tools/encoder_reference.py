"""Computes reference sentence embeddings with sentence-transformers (PyTorch) for the encoder
test. Run once, in a throwaway virtualenv, never in CI (PyTorch is large):

    python3 -m venv /tmp/refenv && /tmp/refenv/bin/pip install sentence-transformers
    /tmp/refenv/bin/python tools/encoder_reference.py ~/.local/share/anymo/models/all-MiniLM-L6-v2 \
        > tokenizer/tests/fixtures/minilm_reference.json
"""
import json
import sys

import sentence_transformers
import torch
from sentence_transformers import SentenceTransformer

SENTENCES = [
    "a person walks forward and then turns around",
    "a dog jumps over something",
    "left upper leg",
    "A horse gallops, then rears up on its hind legs; it neighs loudly.",
    "spine segment",
    "",
]

model = SentenceTransformer(sys.argv[1], device="cpu")
embeddings = model.encode(SENTENCES, normalize_embeddings=True, convert_to_numpy=True)
json.dump(
    {
        "made_by": f"sentence-transformers {sentence_transformers.__version__}, torch {torch.__version__}",
        "sentences": SENTENCES,
        "embeddings": [[round(float(x), 7) for x in row] for row in embeddings],
    },
    sys.stdout,
)
