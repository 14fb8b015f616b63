"""System identification (paper eq. SI): manoeuvres, log formats and the NLP over them."""
